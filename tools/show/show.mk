# stillheart-show: the display segment on a monitor through DRM/KMS (src/kms, src/screen). Built
# everywhere; without libdrm (SH_HAVE_DRM, the Makefile's feature flags) it refuses at start.
SHOW_BIN := $(BUILD)/stillheart-show
$(SHOW_BIN): $(BUILD)/tools/show/main.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) $(DRM_LIBS) -o $@
TOOLS += $(SHOW_BIN)
# The unit tests that reach src/kms link libdrm too (the top rule links LDLIBS_ALL).
$(BUILD)/tests/test_kms: LDLIBS_ALL += $(DRM_LIBS)
# test_show_cli runs the program of the same build.
$(BUILD)/tools/show/tests/test_show_cli.o: CFLAGS_ALL += -DSHOW_BIN='"$(abspath $(BUILD))/stillheart-show"' -Itests/unit
$(BUILD)/tests/test_show_cli: $(BUILD)/tools/show/tests/test_show_cli.o $(BUILD)/tests/unit/shell.o $(LIB) $(SHOW_BIN)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@
TOOL_TESTS += $(BUILD)/tests/test_show_cli
# show-vmwriter: the known frames of make vmtest's display check (tests/vm/show.sh), for the
# QEMU guest only (not stillheart-*: never installed, no page).
SHOW_VMWRITER := $(BUILD)/show-vmwriter
$(SHOW_VMWRITER): $(BUILD)/tools/show/vmwriter.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) -o $@
TOOLS += $(SHOW_VMWRITER)

# make install also installs the unit beside the daemon's (tools/daemon/daemon.mk's folders).
.PHONY: install-show
install: install-show
install-show: all
	install -d $(DESTDIR)$(SYSTEMD_UNIT_DIR) $(DESTDIR)$(PREFIX)/share/doc/stillheart
	sed 's|/usr/local/bin/stillheart|$(PREFIX)/bin/stillheart|; s|/usr/local/share/doc|$(PREFIX)/share/doc|' \
		firmware-config/stillheart-show.service > $(DESTDIR)$(SYSTEMD_UNIT_DIR)/stillheart-show.service
	chmod 0644 $(DESTDIR)$(SYSTEMD_UNIT_DIR)/stillheart-show.service
	install -m 0644 docs/display.md $(DESTDIR)$(PREFIX)/share/doc/stillheart/

# make vmtest-show: the display part of make vmtest alone (tests/vm/show.sh).
.PHONY: vmtest-show
vmtest-show: $(SHOW_BIN) $(SHOW_VMWRITER)
	sh tests/vm/show.sh $(BUILD)
