# The daemon (stillheart run): run demo, daemon tests and bench, install. Its config files' library
# (inih) is set at the top of the Makefile.

# The daemon's tests: a script run by the suite like a cmocka binary (needs the renderer, and
# tools/alloc's allocation counter, built without the sanitizers: it is preloaded into the plain
# build's daemon only).
$(BUILD)/tests/test_daemon: tools/daemon/test_daemon.sh $(APP) $(BUILD)/stillheart-cat $(BUILD)/stillheart-render \
		$(BUILD)/tests/alloc_count.so
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_daemon

$(BUILD)/tests/alloc_count.so: tools/alloc/count.c
	@mkdir -p $(dir $@)
	$(CC) -O1 -Wall -Wextra -Werror -shared -fPIC -o $@ $< -ldl -lpthread

# The control socket's tests: rights by peer credentials, idle clients (needs root for setpriv).
$(BUILD)/tests/test_ctl: tools/daemon/test_ctl.sh $(APP)
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_ctl

# A recording survives its daemon: SIGKILL at random moments, restarts (issue 16).
$(BUILD)/tests/test_record_kill: tools/daemon/test_record_kill.sh $(APP)
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_record_kill

# Memory bounded by the config, not by an input: hostile Y4M headers and damaged streams (issue 16).
$(BUILD)/tests/test_hostile_y4m: tools/daemon/test_hostile_y4m.sh $(APP)
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_hostile_y4m

# The README's ffmpeg path on the live daemon (issue 17; skipped without ffmpeg). The README it
# reads is this tree's, written into the copy.
$(BUILD)/tests/test_video_tools: tools/daemon/test_video_tools.sh README.md $(APP) $(BUILD)/stillheart-cat \
		$(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	sed 's|@README@|$(abspath README.md)|' $< > $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_video_tools

# make run-demo: a short phantom, the daemon on it in real time for a few seconds, and
# stillheart-cat showing that frames arrive (docs/daemon.md). 960x540 (as make demo): at 1080p a
# busy 2-core machine drops frames before the tracker has locked the heart rate, and the demo
# would mostly show raw frames.
RUN_DEMO_DIR ?= out/run-demo
RUN_DEMO_SHM ?= /stillheart-demo
.PHONY: run-demo
run-demo: deps
	$(MAKE) --no-print-directory all
	@[ -s $(RUN_DEMO_DIR)/cam0.y4m ] || $(BUILD)/stillheart-render --preset exvivo --frames 200 --cameras 1 \
		--width 960 --height 540 --out $(RUN_DEMO_DIR)
	@rm -f /dev/shm$(RUN_DEMO_SHM)
	@$(APP) run --source y4m:$(RUN_DEMO_DIR)/cam0.y4m --sink shm:$(RUN_DEMO_SHM) --group= & pid=$$!; \
	  for i in 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20; do [ -e /dev/shm$(RUN_DEMO_SHM) ] && break; sleep 0.1; done; \
	  $(BUILD)/stillheart-cat --name $(RUN_DEMO_SHM) --count 69 --timeout 5 -v > $(RUN_DEMO_DIR)/shown.y4m 2> $(RUN_DEMO_DIR)/cat.log; rc=$$?; \
	  kill -TERM $$pid; wait $$pid; \
	  echo "stillheart-cat read $$(grep -c . $(RUN_DEMO_DIR)/cat.log) frame lines, $$(grep -c stabilized $(RUN_DEMO_DIR)/cat.log) stabilized; shown frames: $(RUN_DEMO_DIR)/shown.y4m (ffplay it)"; \
	  echo "live: $(APP) run --group= --source y4m:$(RUN_DEMO_DIR)/cam0.y4m & then $(BUILD)/stillheart-cat | ffplay -   (stop: kill %1)"; \
	  exit $$rc

# make bench: the daemon replaying a 1080p phantom as fast as possible, 16 tags, 2 threads
# (bench_daemon, then at 4K), and issue 20's trinocular rig in real time, the 3D reference view and
# the stereo pair beside the same in 2D (bench_daemon_3d).
BENCH_DAEMON := $(BUILD)/bench/bench_daemon $(BUILD)/bench/bench_daemon_3d
$(BENCH_DAEMON): $(BUILD)/bench/%: tools/bench/%.sh $(APP) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
BENCH_BIN += $(BENCH_DAEMON)

# make install also installs the unit, the example config (kept when one exists) and udev rules.
SYSTEMD_UNIT_DIR ?= /etc/systemd/system
UDEV_RULES_DIR ?= /etc/udev/rules.d
SYSCONF_DIR ?= /etc/stillheart
.PHONY: install-daemon
install: install-daemon
install-daemon: all
	install -d $(DESTDIR)$(SYSTEMD_UNIT_DIR) $(DESTDIR)$(UDEV_RULES_DIR) $(DESTDIR)$(SYSCONF_DIR) \
		$(DESTDIR)$(PREFIX)/share/doc/stillheart
	sed 's|/usr/local/bin/stillheart|$(PREFIX)/bin/stillheart|; s|/usr/local/share/doc|$(PREFIX)/share/doc|' \
		firmware-config/stillheart.service > $(DESTDIR)$(SYSTEMD_UNIT_DIR)/stillheart.service
	chmod 0644 $(DESTDIR)$(SYSTEMD_UNIT_DIR)/stillheart.service
	install -m 0644 firmware-config/99-stillheart.rules $(DESTDIR)$(UDEV_RULES_DIR)/
	[ -e $(DESTDIR)$(SYSCONF_DIR)/stillheart.ini ] || install -m 0644 firmware-config/stillheart.ini $(DESTDIR)$(SYSCONF_DIR)/
	install -m 0644 docs/daemon.md $(DESTDIR)$(PREFIX)/share/doc/stillheart/
