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
