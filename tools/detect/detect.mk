# The detect stage's test (src/detect: libapriltag, set at the top of the Makefile).
# test_detect renders a phantom frame with the renderer of the same build when there is one.
$(BUILD)/tests/unit/test_detect.o: CFLAGS_ALL += -DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"'
ifeq ($(call have,osmesa)$(call have,apriltag),11)
$(BUILD)/tests/test_detect: | $(BUILD)/stillheart-render
endif
