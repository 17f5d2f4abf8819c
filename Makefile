# stillheart — build, test, benchmark, install.
#   make              library, the `stillheart` command and tools
#   make check        installs Debian deps if missing, checks the include rules (docs/architecture.md),
#                     runs the unit suite, then again under ASan+UBSan, every fuzz harness for a
#                     few seconds (fuzz-check), the VM and aarch64 suites
#   make bench        benchmarks beside their peers (OpenCV cv::remap, ...)
#   make fuzz         every libFuzzer harness for FUZZ_SECONDS each
#   make install      PREFIX=/usr/local DESTDIR= (the programs, their man pages, the library)
#   make man          the man pages (man/) into $(BUILD)/man
# Optional backends are built only when pkg-config (or the header) finds their library: every
# library feature flag (SH_HAVE_*) is set in "library feature flags" below, and nowhere else.

# Cross build (docs/arm64.md, tools/cross/cross.mk): make CROSS_COMPILE=aarch64-linux-gnu- takes
# the cross toolchain, the target's pkg-config folders only (+ libapriltag-dev unpacked by
# scripts/install-deps.sh --arm64) and a build folder of its own.
ifneq ($(CROSS_COMPILE),)
CROSS_ARCH  ?= $(patsubst aarch64,arm64,$(firstword $(subst -, ,$(CROSS_COMPILE))))
CROSS_MULTIARCH := $(CROSS_COMPILE:%-=%)
ARM64_CACHE ?= /var/cache/stillheart/arm64
CC          := $(CROSS_COMPILE)gcc
CXX         := $(CROSS_COMPILE)g++
AR          := $(CROSS_COMPILE)ar
PKG_CONFIG  := PKG_CONFIG_LIBDIR=/usr/lib/$(CROSS_MULTIARCH)/pkgconfig:/usr/share/pkgconfig:$(ARM64_CACHE)/pkgconfig pkg-config
BUILD       ?= build-$(CROSS_ARCH)
endif
CC       ?= cc
CXX      ?= c++
ifeq ($(origin CC),default)
CC       := cc
endif
ifeq ($(origin CXX),default)
CXX      := c++
endif
PKG_CONFIG ?= pkg-config
PREFIX   ?= /usr/local
DESTDIR  ?=
BUILD    ?= build
SAN      ?= 0
FUZZ_SECONDS ?= 30

OPT      ?= -O2
# -fno-math-errno: lrint and sqrt inline (no errno is ever read).
# -ffp-contract=off: the same rounding on every architecture (aarch64 gcc would fuse a*b+c).
COMMON   := $(OPT) -g -fno-math-errno -Wall -Wextra -Werror -ffp-contract=off -fno-strict-aliasing -Iinclude -MMD -MP
CFLAGS_ALL   := -std=c11 -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE $(COMMON) $(CFLAGS)
CXXFLAGS_ALL := -std=c++17 $(COMMON) $(CXXFLAGS)
LDLIBS_ALL   := -lm -lpthread

ifeq ($(SAN),1)
SANFLAGS := -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
CFLAGS_ALL   += $(SANFLAGS)
CXXFLAGS_ALL += $(SANFLAGS)
LDFLAGS      += $(SANFLAGS)
endif

have = $(shell $(PKG_CONFIG) --exists $(1) 2>/dev/null && echo 1)

# Required: qhull_r (Delaunay), Eigen (dense solves), kissfft (the tracker's periodogram).
REQ_PKGS := qhull_r eigen3 kissfft-float
CFLAGS_ALL   += $(shell $(PKG_CONFIG) --cflags qhull_r kissfft-float 2>/dev/null)
# Eigen as a system header: its templates warn under -Werror with our flags.
CXXFLAGS_ALL += $(patsubst -I%,-isystem %,$(shell $(PKG_CONFIG) --cflags eigen3 2>/dev/null))
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs qhull_r kissfft-float 2>/dev/null) -lstdc++

# ---- library feature flags: an optional library found by pkg-config adds its SH_HAVE_* to the
# compile lines and its libraries to every link line; the code without it refuses clearly ----
# libpng: PNG output (src/png, src/imageio).
ifeq ($(call have,libpng),1)
CFLAGS_ALL += -DSH_HAVE_PNG $(shell $(PKG_CONFIG) --cflags libpng)
LDLIBS_ALL += $(shell $(PKG_CONFIG) --libs libpng)
endif
# libturbojpeg: MJPEG decoding (src/pixconv), JPEG files (src/imageio), the bench's peer.
ifeq ($(call have,libturbojpeg),1)
CFLAGS_ALL   += -DSH_HAVE_TURBOJPEG $(shell $(PKG_CONFIG) --cflags libturbojpeg)
CXXFLAGS_ALL += -DSH_HAVE_TURBOJPEG
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs libturbojpeg)
endif
# libgpiod 1.6: GPIO trigger lines (src/sync/gpio.c), the v1 API (2.x is a different API).
ifeq ($(call have,libgpiod),1)
ifneq ($(shell $(PKG_CONFIG) --atleast-version=2 libgpiod && echo 2),2)
CFLAGS_ALL   += -DSH_HAVE_GPIOD
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs libgpiod)
endif
endif
# libcamera (src/source/libcamera.cpp): its headers as system headers (they warn under -Werror).
ifeq ($(call have,libcamera),1)
CXXFLAGS_ALL += -DSH_HAVE_LIBCAMERA $(patsubst -I%,-isystem %,$(shell $(PKG_CONFIG) --cflags libcamera))
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs libcamera)
endif
# inih: the daemon's config files (src/config/ini.c).
ifeq ($(call have,inih),1)
CFLAGS_ALL += -DSH_HAVE_INIH $(shell $(PKG_CONFIG) --cflags inih)
LDLIBS_ALL += $(shell $(PKG_CONFIG) --libs inih)
endif
# libdrm: the KMS output (src/kms) of stillheart-show. Its library goes only on the link lines
# that reach src/kms (DRM_LIBS, tools/show/show.mk): the daemon and the other programs never
# call it and need not depend on it.
ifeq ($(call have,libdrm),1)
CFLAGS_ALL += -DSH_HAVE_DRM $(shell $(PKG_CONFIG) --cflags libdrm)
DRM_LIBS   := $(shell $(PKG_CONFIG) --libs libdrm)
endif
# libapriltag: the detect stage (src/detect). Debian's apriltag.pc omits -lapriltag-utils, which
# holds the image_u8_* helpers.
ifeq ($(call have,apriltag),1)
CFLAGS_ALL   += -DSH_HAVE_APRILTAG
CXXFLAGS_ALL += -DSH_HAVE_APRILTAG
LDLIBS_ALL   += $(shell $(PKG_CONFIG) --libs apriltag) -lapriltag-utils
endif

# OpenCV, for benchmarks and test oracles only (Debian's -core/-imgproc packages ship no .pc).
OPENCV_INC := $(if $(CROSS_COMPILE),,$(firstword $(wildcard /usr/include/opencv4)))
ifneq ($(OPENCV_INC),)
OPENCV_CFLAGS := -I$(OPENCV_INC)
OPENCV_LIBS   := -lopencv_imgproc -lopencv_core
endif

# ---- the library: every module folder under src/ except the programs ----
LIB_DIRS := $(filter-out src/app,$(wildcard src/*))
LIB_C    := $(foreach d,$(LIB_DIRS),$(wildcard $(d)/*.c))
LIB_CXX  := $(foreach d,$(LIB_DIRS),$(wildcard $(d)/*.cpp))
LIB_OBJ  := $(LIB_C:%.c=$(BUILD)/%.o) $(LIB_CXX:%.cpp=$(BUILD)/%.o)
LIB      := $(BUILD)/libstillheart.a

APP_OBJ  := $(patsubst %.c,$(BUILD)/%.o,$(wildcard src/app/*.c))
APP      := $(BUILD)/stillheart

TEST_SRC := $(wildcard tests/unit/test_*.c)
TEST_BIN := $(TEST_SRC:tests/unit/%.c=$(BUILD)/tests/%)
TEST_SUPPORT := $(patsubst %.c,$(BUILD)/%.o,$(filter-out $(TEST_SRC),$(wildcard tests/unit/*.c)) tools/synth/synth.c)

.PHONY: all deps tests check check-asan bench fuzz demo install clean
all: $(LIB) $(APP)

deps:
	@sh scripts/install-deps.sh

# ---- per-module optimisation: $(OPT) everywhere but in this table. -O3 lets gcc vectorize the
# per-pixel loops, each measured in make bench: src/warp the position fill (bench_warp) and the
# outside fill (bench_outside), src/pixconv the pixel-format loops (bench_pixconv), src/screen the
# display's YUV to XRGB rows (bench_screen), src/flow the pyramid's 16-bit reduction (bench_flow),
# src/landmarks the band-pass's column sums (stillheart-eval --landmarks, time per frame),
# src/linalg the per-frame LU's row updates (lu.c; the daemon's landmarks, --stats model time) ----
$(BUILD)/src/warp/%.o:    CFLAGS_ALL += -O3
$(BUILD)/src/pixconv/%.o: CFLAGS_ALL += -O3
$(BUILD)/src/screen/%.o:  CFLAGS_ALL += -O3
$(BUILD)/src/flow/%.o:    CFLAGS_ALL += -O3
$(BUILD)/src/landmarks/%.o: CFLAGS_ALL += -O3
$(BUILD)/src/linalg/%.o:  CFLAGS_ALL += -O3

$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -c $< -o $@

$(BUILD)/%.o: %.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS_ALL) -c $< -o $@

$(LIB): $(LIB_OBJ)
	@mkdir -p $(dir $@)
	rm -f $@
	$(AR) rcs $@ $^

$(APP): $(APP_OBJ) $(LIB)
	$(CC) $(LDFLAGS) $(APP_OBJ) $(LIB) $(LDLIBS_ALL) -o $@

$(BUILD)/tests/unit/%.o: CFLAGS_ALL += -Itools/synth

$(BUILD)/tests/%: $(BUILD)/tests/unit/%.o $(TEST_SUPPORT) $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(TEST_SUPPORT) $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

tests: $(TEST_BIN) $(APP)

# Oracle tests (tests/oracle/*.cpp, C++): a module against the OpenCV function it stands in for,
# on host builds that have OpenCV's headers (install-deps installs them; the aarch64 build has
# no OpenCV, and its unit tests check the same code against closed forms).
ifneq ($(wildcard $(OPENCV_INC)/opencv2/video/tracking.hpp),)
ORACLE_BIN := $(patsubst tests/oracle/%.cpp,$(BUILD)/tests/%,$(wildcard tests/oracle/test_*.cpp))
$(ORACLE_BIN): $(BUILD)/tests/%: tests/oracle/%.cpp $(BUILD)/tools/synth/synth.o $(LIB)
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS_ALL) $(OPENCV_CFLAGS) -Itools/synth $< $(BUILD)/tools/synth/synth.o $(LIB) \
		$(shell $(PKG_CONFIG) --libs cmocka) -lopencv_video $(OPENCV_LIBS) $(LDLIBS_ALL) -o $@
tests: $(ORACLE_BIN)
endif

# The suite: the include and link rules of docs/architecture.md (scripts/check-includes.sh, which
# first shows on planted violations that it catches them), unit tests plain, then under ASan+UBSan, then the capture code against the kernel's
# own drivers in a QEMU guest (make vmtest, about 20 s once its kernel is cached), then the
# aarch64 build's suite under qemu-aarch64 (make check-arm64, tools/cross/cross.mk); one summary
# line at the end counts all four. CHECK_ARM64=0 leaves the aarch64 part out. The fuzzers and the
# guests run side by side: each runs one process at a time (a harness after another, qemu -smp 1),
# so one after the other they left a core idle for about three minutes (2026-12-06).
CHECK_JOBS  ?= $(shell nproc)
CHECK_ARM64 ?= 1
# $(BUILD)/check.times: when each phase ended (tests/run-tests.sh prints them before the summary).
CHECK_T = $(BUILD)/check.times
CHECK_SINCE = $$(($$(date +%s) - $$(sed -n 's/^start //p' $(CHECK_T))))
check: deps
	@mkdir -p $(BUILD) && echo "start $$(date +%s)" > $(CHECK_T)
	$(MAKE) --no-print-directory -j$(CHECK_JOBS) tests
	$(MAKE) --no-print-directory check-includes
	$(MAKE) --no-print-directory -j$(CHECK_JOBS) BUILD=build-asan SAN=1 OPT=-O1 tests
	@echo "builds $(CHECK_SINCE)" >> $(CHECK_T)
	@$(MAKE) --no-print-directory -j$(CHECK_JOBS) fuzz-check > $(BUILD)/fuzz.out 2>&1 & \
	  $(MAKE) --no-print-directory vmtest > $(BUILD)/vmtest.out 2>&1; wait; \
	  grep '^fuzz' $(BUILD)/fuzz.out; tail -n 25 $(BUILD)/vmtest.out; echo "fuzz-and-guests $(CHECK_SINCE)" >> $(CHECK_T)
	@rm -f $(BUILD)/arm64.out; if [ "$(CHECK_ARM64)" = 1 ]; then \
	  $(MAKE) --no-print-directory check-arm64 > $(BUILD)/arm64.out 2>&1; \
	  grep -E '^(\[  (FAILED|ERROR) |crashed|[0-9]+ passed, )' $(BUILD)/arm64.out | sed 's/^/arm64: /'; \
	  echo "aarch64 $(CHECK_SINCE)" >> $(CHECK_T); fi
	@VMTEST_OUT=$(BUILD)/vmtest.out FUZZ_OUT=$(BUILD)/fuzz.out ARM64_OUT=$(if $(filter 1,$(CHECK_ARM64)),$(BUILD)/arm64.out) \
	  CHECK_TIMES=$(CHECK_T) sh tests/run-tests.sh build build-asan

.PHONY: check-includes
check-includes: $(APP)
	@sh scripts/check-includes.sh --self-test --build $(BUILD)
	@sh scripts/check-includes.sh --build $(BUILD)

check-asan:
	$(MAKE) --no-print-directory BUILD=build-asan SAN=1 OPT=-O1 tests
	@sh tests/run-tests.sh build-asan

# ---- benchmarks (tools/bench): ours beside the peer, in one process ----
BENCH_SRC := $(wildcard tools/bench/*.cpp)
BENCH_BIN := $(BENCH_SRC:tools/bench/%.cpp=$(BUILD)/bench/%)
# `stillheart warp`'s whole process beside a Python cv2.remap script (issue 20), which it carries
BENCH_WARP_PROCESS := $(BUILD)/bench/bench_warp_process
$(BENCH_WARP_PROCESS): tools/bench/bench_warp_process.sh tools/bench/warp_remap.py $(APP) $(BUILD)/stillheart-synth
	@mkdir -p $(dir $@)
	cp tools/bench/warp_remap.py $(dir $@)
	cp $< $@
	chmod +x $@
BENCH_BIN += $(BENCH_WARP_PROCESS)
$(BUILD)/bench/%: tools/bench/%.cpp $(BUILD)/tools/synth/synth.o $(LIB)
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS_ALL) $(OPENCV_CFLAGS) $< $(BUILD)/tools/synth/synth.o $(LIB) $(OPENCV_LIBS) $(LDLIBS_ALL) -o $@

# bench_flow's and bench_landmarks' peer, cv::calcOpticalFlowPyrLK, lives in OpenCV's video module
$(BUILD)/bench/bench_flow $(BUILD)/bench/bench_landmarks: OPENCV_LIBS += -lopencv_video

bench: deps
	@sh scripts/install-deps.sh --bench
	$(MAKE) --no-print-directory $(BENCH_BIN)
	@for b in $(BENCH_BIN); do echo "== $$b"; $$b || exit 1; done

# ---- fuzzing (clang + libFuzzer) ----
FUZZ_SRC := $(wildcard tests/fuzz/fuzz_*.c)
FUZZ_BIN := $(FUZZ_SRC:tests/fuzz/%.c=build-fuzz/%)
FUZZ_FLAGS := -std=c11 -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE -g -O1 -Iinclude \
	-fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all
# Linked by clang++: a harness that reaches the library's C++ objects (src/linalg's Eigen, through
# the interpolation methods; src/source's libcamera, through the clock) needs the C++ sanitizer
# runtime, and it costs the others nothing.
# The instrumented library once per make (its own make, which knows the header dependencies),
# before any harness: harnesses built side by side (make -j) must not each build it.
FUZZ_LIB := build-fuzz/lib/libstillheart.a
ifneq ($(BUILD),build-fuzz/lib)
.PHONY: fuzz-lib
fuzz-lib:
	@mkdir -p build-fuzz
	$(MAKE) --no-print-directory BUILD=build-fuzz/lib CC=clang CXX=clang++ SAN=0 \
		CFLAGS="-fsanitize=fuzzer-no-link,address,undefined" \
		CXXFLAGS="-fsanitize=fuzzer-no-link,address,undefined" $(FUZZ_LIB)
endif
build-fuzz/%: tests/fuzz/%.c fuzz-lib
	clang $(FUZZ_FLAGS) $(shell $(PKG_CONFIG) --cflags qhull_r kissfft-float) -c $< -o build-fuzz/$*.o
	clang++ -fsanitize=fuzzer,address,undefined build-fuzz/$*.o build-fuzz/lib/libstillheart.a \
		$(filter-out -lstdc++,$(LDLIBS_ALL)) -o $@

# make check: every harness for FUZZ_CHECK_SECONDS on its seed corpus (and what earlier runs
# found, build-fuzz/corpus), so that a parser that crashes on its own seeds or on what a few
# seconds of mutation make of them fails the suite; one line per harness and a closing
# "fuzz: N passed, N failed" that tests/run-tests.sh counts. make fuzz runs them for longer.
FUZZ_CHECK_SECONDS ?= 3
.PHONY: fuzz-check
fuzz-check: $(FUZZ_BIN)
	@p=0; f=0; for h in $(FUZZ_BIN); do n=$$(basename $$h); mkdir -p build-fuzz/corpus/$$n; \
	  if $$h -max_total_time=$(FUZZ_CHECK_SECONDS) -print_final_stats=1 build-fuzz/corpus/$$n tests/fuzz/corpus/$$n \
	    > build-fuzz/$$n.log 2>&1; then p=$$((p + 1)); \
	    echo "fuzz: $$n: $$(sed -n 's/^stat::number_of_executed_units: *//p' build-fuzz/$$n.log) runs, no crash"; \
	  else f=$$((f + 1)); echo "fuzz: $$n: FAILED (build-fuzz/$$n.log)"; tail -30 build-fuzz/$$n.log; fi; \
	done; echo "fuzz: $$p passed, $$f failed"

fuzz: deps $(FUZZ_BIN)
	@for f in $(FUZZ_BIN); do n=$$(basename $$f); echo "== $$n ($(FUZZ_SECONDS) s)"; \
		mkdir -p build-fuzz/corpus/$$n; \
		$$f -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 build-fuzz/corpus/$$n tests/fuzz/corpus/$$n \
			2>build-fuzz/$$n.log || { tail -40 build-fuzz/$$n.log; exit 1; }; \
		grep -E 'stat::number_of_executed_units' build-fuzz/$$n.log; done

# Tools (tools/<name>/) bring their own rules in a fragment: tools/<name>/<name>.mk. A fragment
# adds its programs to TOOLS (built by `make`), its tests to TOOL_TESTS (run by `make check`).
TOOLS :=
TOOL_TESTS :=
-include $(wildcard tools/*/*.mk)
all: $(TOOLS)
# unit tests run the programs too (stillheart, stillheart-cat, ...)
tests: $(TOOL_TESTS) $(TOOLS)

# make demo: a recording with a known motion, stabilized offline, e printed (README, make targets).
DEMO_DIR ?= out/demo
DEMO_METHOD ?= tps
demo: deps
	$(MAKE) --no-print-directory all
	$(BUILD)/stillheart-synth --width 960 --height 540 --frames 30 --markers 16 --out $(DEMO_DIR)
	$(APP) warp --method $(DEMO_METHOD) --threads 2 --metric --points $(DEMO_DIR)/points.csv \
		$(DEMO_DIR)/video.y4m $(DEMO_DIR)/stabilized.y4m --map-out $(DEMO_DIR)/map.npy
	@echo "stabilized video: $(DEMO_DIR)/stabilized.y4m (e.g. ffplay $(DEMO_DIR)/stabilized.y4m)"

# The programs for users, installed where they are built (stillheart-calib needs OpenCV); not
# stillheart-vmprobe, which runs inside make vmtest's guest only.
USER_TOOLS := stillheart-cat stillheart-show stillheart-render stillheart-eval stillheart-trackeval stillheart-synth \
	stillheart-calib
install: all
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/include/stillheart $(DESTDIR)$(PREFIX)/lib
	install -m 0755 $(APP) $(filter $(addprefix $(BUILD)/,$(USER_TOOLS)),$(TOOLS)) $(DESTDIR)$(PREFIX)/bin/
	install -m 0644 include/stillheart/*.h $(DESTDIR)$(PREFIX)/include/stillheart/
	install -m 0644 $(LIB) $(DESTDIR)$(PREFIX)/lib/

# Every build folder the rules make: the default and the ASan build, the fuzzers', the aarch64
# build (tools/cross/cross.mk), the Debian packages' copy, and a BUILD= given on the command line.
clean:
	rm -rf build build-asan build-fuzz $(ARM64_BUILD) $(DEB_OUT) $(BUILD)

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)
