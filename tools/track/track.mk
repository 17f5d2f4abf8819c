# The tracker's evaluation on the phantom's analytic truth (tools/track): stillheart-trackeval
# prints the figures of docs/tracking.md; test_track_phantom holds the issue's quality bars.
# Needs only libphantom (libc, libm), so it builds everywhere the library does.
TRACKSIM_OBJ := $(BUILD)/tools/track/sim.o

$(BUILD)/tools/track/%.o: CFLAGS_ALL += -Itools/phantom -Itools/track

$(BUILD)/stillheart-trackeval: $(BUILD)/tools/track/trackeval.o $(TRACKSIM_OBJ) $(BUILD)/libphantom.a $(LIB)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(LDLIBS_ALL) -o $@

TOOLS += $(BUILD)/stillheart-trackeval

$(BUILD)/tests/test_track_phantom: $(BUILD)/tools/track/tests/test_track_phantom.o $(TRACKSIM_OBJ) \
		$(BUILD)/libphantom.a $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) \
		$(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_track_phantom

# `stillheart track` from the outside, and the issue's end-to-end bar (stabilizing from its points
# within 10 % of stabilizing from the truth): drives this build's binaries.
$(BUILD)/tools/track/tests/test_track_cli.o: CFLAGS_ALL += -DAPP_BIN='"$(abspath $(BUILD))/stillheart"' \
	-DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"' -DEVAL_BIN='"$(abspath $(BUILD))/stillheart-eval"'
$(BUILD)/tests/test_track_cli: $(BUILD)/tools/track/tests/test_track_cli.o $(LIB) | $(BUILD)/stillheart \
		$(BUILD)/stillheart-eval
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@
ifeq ($(call have,osmesa),1)
$(BUILD)/tests/test_track_cli: | $(BUILD)/stillheart-render
endif

TOOL_TESTS += $(BUILD)/tests/test_track_cli

# Issue 18's whole bar for `stillheart track` without --ids: every heart marker and no decoy kept,
# both presets with --occlusions, 30, 120 and 400 frames, seeds 1-8 (48 renders; `make check`
# runs seed 1). Several minutes: docs/tracking.md has the figures.
.PHONY: check-auto-ids
check-auto-ids: $(BUILD)/tests/test_track_cli
	SH_AUTO_IDS_SEEDS=8 $(BUILD)/tests/test_track_cli
