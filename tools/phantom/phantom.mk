# The phantom model and ground-truth library (tools/phantom): libc, libm and libstillheart only,
# so the evaluator can link it on machines without OSMesa. Its tests render sequences, so they
# live in tools/render/render.mk.
PHANTOM_OBJ := $(patsubst %.c,$(BUILD)/%.o,$(wildcard tools/phantom/*.c))

$(BUILD)/libphantom.a: $(PHANTOM_OBJ)
	@mkdir -p $(dir $@)
	rm -f $@
	$(AR) rcs $@ $^

TOOLS += $(BUILD)/libphantom.a

# The phantom's calibrations against the load checks of calib.h (no rendering: libphantom only).
$(BUILD)/tools/phantom/tests/test_phantom_calib.o: tools/phantom/tests/test_phantom_calib.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS_ALL) -c $< -o $@

$(BUILD)/tests/test_phantom_calib: $(BUILD)/tools/phantom/tests/test_phantom_calib.o $(BUILD)/libphantom.a $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/libphantom.a $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_phantom_calib
