# stillheart-calib (tools/calib): the rig's calibration with OpenCV's calib3d. A tool, never the
# daemon. Built where the OpenCV headers are (not in the cross build, whose OPENCV_INC is empty);
# its test renders the board with stillheart-render, so it needs OSMesa + libapriltag as well.
ifneq ($(wildcard $(OPENCV_INC)/opencv2/calib3d.hpp),)

CALIB_OBJ := $(patsubst %.cpp,$(BUILD)/%.o,$(wildcard tools/calib/*.cpp))
CALIB_BIN := $(BUILD)/stillheart-calib

$(BUILD)/tools/calib/%.o: CXXFLAGS_ALL += $(OPENCV_CFLAGS)

$(CALIB_BIN): $(CALIB_OBJ) $(LIB)
	$(CXX) $(LDFLAGS) $(CALIB_OBJ) $(LIB) -lopencv_calib3d $(OPENCV_LIBS) $(LDLIBS_ALL) -o $@

TOOLS += $(CALIB_BIN)

ifeq ($(call have,osmesa)$(call have,apriltag),11)
$(BUILD)/tools/calib/tests/%.o: tools/calib/tests/%.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -Itools/phantom/tests -DCALIB_BIN='"$(abspath $(CALIB_BIN))"' \
		-DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"' -c $< -o $@

$(BUILD)/tests/test_calib: $(BUILD)/tools/calib/tests/test_calib.o $(BUILD)/tools/phantom/tests/phantom_testutil.o \
		$(LIB) $(CALIB_BIN) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_calib
endif

endif
