# The detect stage (src/detect, libapriltag) and image file reading (src/imageio: libpng,
# libturbojpeg). The top Makefile compiles src/*/ into the library; this fragment adds the
# optional libraries when pkg-config finds them. Debian's apriltag.pc omits -lapriltag-utils,
# which holds the image_u8_* helpers.
ifeq ($(call have,apriltag),1)
CFLAGS_ALL   += -DSH_HAVE_APRILTAG
CXXFLAGS_ALL += -DSH_HAVE_APRILTAG
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs apriltag) -lapriltag-utils
endif
ifeq ($(call have,libturbojpeg),1)
CFLAGS_ALL   += -DSH_HAVE_TURBOJPEG $(shell $(PKG_CONFIG) --cflags libturbojpeg)
CXXFLAGS_ALL += -DSH_HAVE_TURBOJPEG
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs libturbojpeg)
endif

# test_detect renders a phantom frame with the renderer of the same build when there is one.
$(BUILD)/tests/unit/test_detect.o: CFLAGS_ALL += -DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"'
ifeq ($(call have,osmesa)$(call have,apriltag),11)
$(BUILD)/tests/test_detect: | $(BUILD)/stillheart-render
endif
