# stillheart-cat: the shared-memory display buffer as Y4M on stdout.
CAT_BIN := $(BUILD)/stillheart-cat
$(CAT_BIN): $(BUILD)/tools/cat/main.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) -o $@
TOOLS += $(CAT_BIN)
