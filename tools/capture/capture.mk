# Capture's tests and tools (src/source, src/pixconv, src/sync, src/record; docs/capture.md). Its
# libraries (libturbojpeg, libgpiod, libcamera) and pixconv's -O3 are set at the top of the Makefile.
# test_pixconv compares with OpenCV's cvtColor (tools/capture/cv_oracle.cpp) when it is there;
# the top rule links $< only, so the oracle object rides in LDLIBS_ALL of that one binary.
ifneq ($(OPENCV_INC),)
$(BUILD)/tests/unit/test_pixconv.o: CFLAGS_ALL += -DSH_HAVE_OPENCV_ORACLE -Itools/capture
$(BUILD)/tools/capture/cv_oracle.o: CXXFLAGS_ALL += $(OPENCV_CFLAGS)
$(BUILD)/tests/test_pixconv: $(BUILD)/tools/capture/cv_oracle.o
$(BUILD)/tests/test_pixconv: LDLIBS_ALL += $(BUILD)/tools/capture/cv_oracle.o $(OPENCV_LIBS) -lstdc++
# make pixconv-ref: rewrites tests/ref/pixconv_ref.h, the same oracle's output stored for builds
# without OpenCV (the aarch64 one); through a temporary file, so a failed run leaves the old one.
$(BUILD)/tools/capture/make_pixconv_ref.o: CFLAGS_ALL += -Itools/capture
$(BUILD)/make_pixconv_ref: $(BUILD)/tools/capture/make_pixconv_ref.o $(BUILD)/tools/capture/cv_oracle.o
	$(CC) $(LDFLAGS) $^ $(OPENCV_LIBS) -lstdc++ -o $@
.PHONY: pixconv-ref
pixconv-ref: $(BUILD)/make_pixconv_ref
	$< > tests/ref/pixconv_ref.h.tmp && mv tests/ref/pixconv_ref.h.tmp tests/ref/pixconv_ref.h
endif

# test_record_cli runs `stillheart record` of the same build (the ASan build tests the ASan one).
$(BUILD)/tools/capture/tests/test_record_cli.o: CFLAGS_ALL += -DRECORD_BIN='"$(abspath $(BUILD))/stillheart"' -Itests/unit
$(BUILD)/tests/test_record_cli: $(BUILD)/tools/capture/tests/test_record_cli.o $(BUILD)/tests/unit/shell.o $(LIB) \
		$(BUILD)/stillheart
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@
TOOL_TESTS += $(BUILD)/tests/test_record_cli

# stillheart-vmprobe: the capture checks run inside the QEMU guest of tests/vm/run.sh.
VMPROBE_BIN := $(BUILD)/stillheart-vmprobe
$(VMPROBE_BIN): $(BUILD)/tools/capture/vmprobe.o $(BUILD)/tools/capture/vmprobe_run.o \
		$(BUILD)/tools/capture/vmprobe_loop.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) -o $@
TOOLS += $(VMPROBE_BIN)

# make vmtest: stillheart's capture code against the kernel's vivid driver in a QEMU guest
# (tests/vm/run.sh; downloads the kernel once into /var/cache/stillheart/vm), then the display
# on the kernel's bochs DRM driver (tests/vm/show.sh, tools/show/show.mk); each prints its own
# "vmtest: N passed, N failed" (tests/run-tests.sh adds them up), both run whatever the first gives.
.PHONY: vmtest
vmtest: $(VMPROBE_BIN) $(APP) $(BUILD)/stillheart-cat $(BUILD)/stillheart-render $(BUILD)/stillheart-show $(BUILD)/show-vmwriter
	@rc=0; sh tests/vm/run.sh $(BUILD) || rc=1; sh tests/vm/show.sh $(BUILD) || rc=1; exit $$rc
