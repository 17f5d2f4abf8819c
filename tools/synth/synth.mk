# stillheart-synth: a recording with a known motion, for the demo and for quick trials.
SYNTH_BIN := $(BUILD)/stillheart-synth
$(BUILD)/tools/synth/%.o: CFLAGS_ALL += -Itools/synth
$(SYNTH_BIN): $(BUILD)/tools/synth/main.o $(BUILD)/tools/synth/synth.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) -o $@
TOOLS += $(SYNTH_BIN)
