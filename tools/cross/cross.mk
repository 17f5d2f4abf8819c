# The aarch64 build tested under emulation (docs/arm64.md). Needs scripts/install-deps.sh --arm64.
#   make check-arm64     the unit suite built with aarch64-linux-gnu- and run under qemu-aarch64
# binfmt_misc is not available here: tools/cross/qemu-wrap.sh puts each aarch64 program of the
# build folder behind a script that runs it under qemu-aarch64 (the tests exec the programs too).
ARM64_BUILD ?= build-arm64
.PHONY: check-arm64 deps-arm64
deps-arm64:
	@sh scripts/install-deps.sh --arm64

# The tests that take minutes under emulation (the phantom renders, the tracker on the phantom's
# truth, the warps, the landmarks' daemon runs) run side by side, each in a lane of its own
# (tools/cross/run-lanes.sh); the rest one after another; ARM64_LANES= runs everything one after
# another. test_eval_landmarks has its own since 2026-12-04: in the rest's lane (823 s then, of
# it 403 s) that lane was the last to end, alone on one core for about three minutes.
ARM64_JOBS  ?= $(shell nproc)
ARM64_LANES ?= test_render test_track_phantom test_warp3d_phantom test_warp3d test_warp test_phantom_truth \
               test_daemon test_track_cli test_eval_landmarks
# The phantom fixtures of the other tests come from the host build's renderer (SH_TEST_RENDER,
# tools/cross/qemu-wrap.sh); test_render tests the aarch64 renderer itself.
check-arm64: deps-arm64 $(BUILD)/stillheart-render
	$(MAKE) --no-print-directory -j$(ARM64_JOBS) CROSS_COMPILE=aarch64-linux-gnu- BUILD=$(ARM64_BUILD) tests
	@sh tools/cross/qemu-wrap.sh $(ARM64_BUILD)
	@QEMU_LD_PREFIX=/ SH_TEST_RENDER=$(abspath $(BUILD))/stillheart-render \
		sh tools/cross/run-lanes.sh $(ARM64_BUILD) $(ARM64_LANES)

# make check-arm64 ARM64_LOOP times in a row, stopping at the first failure (issue 21; a quiet
# machine: tools/cross/check-arm64-loop.sh says why).
ARM64_LOOP ?= 10
.PHONY: check-arm64-loop
check-arm64-loop:
	@sh tools/cross/check-arm64-loop.sh $(ARM64_LOOP)

# build/tests/test_daemon LOAD_LOOP times in a row on the host with two busy loops beside it
# (issue 21; tools/cross/daemon-load-loop.sh says why two).
LOAD_LOOP ?= 10
.PHONY: test-daemon-load-loop
test-daemon-load-loop: tests
	@BUILD=$(BUILD) sh tools/cross/daemon-load-loop.sh $(LOAD_LOOP)

# ---- Debian packages (debian/): make deb [DEB_ARCHS="amd64 arm64"] -> build-deb/*.deb ----
# Built from a copy of the working tree (dpkg-buildpackage writes beside the source folder).
# arm64 is a cross build: -d because libapriltag-dev:arm64 cannot co-install with the amd64
# one (the Makefile's cross switch finds the unpacked copy of install-deps --arm64).
DEB_ARCHS ?= amd64 arm64
DEB_OUT   ?= build-deb
.PHONY: deb
deb:
	rm -rf $(DEB_OUT) && mkdir -p $(DEB_OUT)/src
	git ls-files -co --exclude-standard | while read -r f; do [ -e "$$f" ] && echo "$$f"; done | \
		grep -v '^build' | tar -cf - -T - | tar -xf - -C $(DEB_OUT)/src
	@for a in $(DEB_ARCHS); do \
		if [ "$$a" = "$$(dpkg --print-architecture)" ]; then opts=""; else opts="-a $$a -d"; fi; \
		echo "== dpkg-buildpackage $$opts"; \
		(cd $(DEB_OUT)/src && dpkg-buildpackage -b -us -uc $$opts) > $(DEB_OUT)/build-$$a.log 2>&1 || \
			{ tail -30 $(DEB_OUT)/build-$$a.log; exit 1; }; \
	done
	@ls $(DEB_OUT)/*.deb
	@for c in $(DEB_OUT)/*.changes; do echo "== lintian $$c"; lintian --fail-on error $$c || exit 1; done

# make deb-test: the built packages installed into a fresh debootstrap'd Debian 12 root (as root).
.PHONY: deb-test
deb-test:
	sh tools/cross/deb-test.sh $(DEB_OUT)
