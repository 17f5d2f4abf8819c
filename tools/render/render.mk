# stillheart-render (OSMesa + libapriltag) and the phantom's tests. Built only when both are found.
# Prerequisites name $(BUILD)/libphantom.a literally: fragments are included in any order.
ifeq ($(call have,osmesa)$(call have,apriltag),11)

RENDER_OBJ  := $(patsubst %.c,$(BUILD)/%.o,$(wildcard tools/render/*.c))
RENDER_LIBS := $(shell $(PKG_CONFIG) --libs osmesa apriltag) -lapriltag-utils
CMOCKA_LIBS := $(shell $(PKG_CONFIG) --libs cmocka)

$(BUILD)/stillheart-render: $(RENDER_OBJ) $(BUILD)/libphantom.a $(LIB)
	$(CC) $(LDFLAGS) $(RENDER_OBJ) $(BUILD)/libphantom.a $(LIB) $(RENDER_LIBS) $(LDLIBS_ALL) -o $@

TOOLS += $(BUILD)/stillheart-render

# Tests run the renderer binary of the same build (the ASan build tests the ASan renderer).
RENDER_TEST_DEFS := -DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"'

$(BUILD)/tools/phantom/tests/%.o: tools/phantom/tests/%.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) $(RENDER_TEST_DEFS) -c $< -o $@

$(BUILD)/tools/render/tests/%.o: tools/render/tests/%.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) $(RENDER_TEST_DEFS) -c $< -o $@

$(BUILD)/tests/test_phantom_truth: $(BUILD)/tools/phantom/tests/test_phantom_truth.o \
		$(BUILD)/tools/phantom/tests/phantom_testutil.o $(BUILD)/libphantom.a $(LIB) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(CMOCKA_LIBS) $(LDLIBS_ALL) -o $@

$(BUILD)/tests/test_render: $(BUILD)/tools/render/tests/test_render.o \
		$(BUILD)/tools/phantom/tests/phantom_testutil.o $(BUILD)/libphantom.a $(LIB) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(CMOCKA_LIBS) \
		$(shell $(PKG_CONFIG) --libs apriltag) -lapriltag-utils $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_phantom_truth $(BUILD)/tests/test_render

# The calibration round trip against OpenCV's projectPoints (C++, the only C++ here).
ifneq ($(wildcard $(OPENCV_INC)/opencv2/calib3d.hpp),)
$(BUILD)/tools/phantom/tests/test_phantom_opencv.o: tools/phantom/tests/test_phantom_opencv.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS_ALL) $(OPENCV_CFLAGS) $(RENDER_TEST_DEFS) -c $< -o $@

$(BUILD)/tests/test_phantom_opencv: $(BUILD)/tools/phantom/tests/test_phantom_opencv.o \
		$(BUILD)/tools/phantom/tests/phantom_testutil.o $(BUILD)/libphantom.a $(LIB) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	$(CXX) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(CMOCKA_LIBS) \
		-lopencv_calib3d $(OPENCV_LIBS) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_phantom_opencv
endif

endif
