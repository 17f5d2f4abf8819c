# The phantom model and ground-truth library (tools/phantom): libc, libm and libstillheart only,
# so the evaluator can link it on machines without OSMesa. Its tests render sequences, so they
# live in tools/render/render.mk.
PHANTOM_OBJ := $(patsubst %.c,$(BUILD)/%.o,$(wildcard tools/phantom/*.c))

$(BUILD)/libphantom.a: $(PHANTOM_OBJ)
	@mkdir -p $(dir $@)
	rm -f $@
	$(AR) rcs $@ $^

TOOLS += $(BUILD)/libphantom.a
