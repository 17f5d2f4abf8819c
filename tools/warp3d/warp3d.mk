# 3D stabilization's tests on rendered phantoms (tools/warp3d/tests): 3D against 2D on the same
# sequence, the PLY export against the phantom's true surface. They drive the build's own
# stillheart-render, so they exist only where it does (OSMesa + libapriltag).
# Prerequisites name $(BUILD)/libphantom.a literally: fragments are included in any order.
ifeq ($(call have,osmesa)$(call have,apriltag),11)

$(BUILD)/tools/warp3d/tests/%.o: tools/warp3d/tests/%.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -Itools/phantom -Itools/phantom/tests \
		-DAPP_BIN='"$(abspath $(BUILD))/stillheart"' -DEVAL_BIN='"$(abspath $(BUILD))/stillheart-eval"' -c $< -o $@

$(BUILD)/tests/test_warp3d_phantom: $(BUILD)/tools/warp3d/tests/test_warp3d_phantom.o \
		$(BUILD)/tools/phantom/tests/phantom_testutil.o $(BUILD)/libphantom.a $(LIB) $(BUILD)/stillheart-render \
		$(APP) $(BUILD)/stillheart-eval
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $(filter %.o,$^) $(BUILD)/libphantom.a $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) \
		$(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_warp3d_phantom

endif
