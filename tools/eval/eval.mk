# stillheart-eval (tools/eval): the paper's metric e, heatmaps, the geometric error on phantom
# sequences; `make table2` reproduces the paper's Table II on rendered phantoms.
# Prerequisites name $(BUILD)/libphantom.a literally: fragments are included in any order.
EVAL_OBJ := $(patsubst %.c,$(BUILD)/%.o,$(wildcard tools/eval/*.c))
EVAL_BIN := $(BUILD)/stillheart-eval

$(BUILD)/tools/eval/%.o: CFLAGS_ALL += -Itools/phantom

$(EVAL_BIN): $(EVAL_OBJ) $(BUILD)/libphantom.a $(LIB)
	$(CC) $(LDFLAGS) $(EVAL_OBJ) $(BUILD)/libphantom.a $(LIB) $(LDLIBS_ALL) -o $@

TOOLS += $(EVAL_BIN)

# The test drives the binary of the same build (the ASan build tests the ASan evaluator).
$(BUILD)/tools/eval/tests/test_eval.o: CFLAGS_ALL += -DEVAL_BIN='"$(abspath $(BUILD))/stillheart-eval"' -Itests/ref \
	-DAPP_BIN='"$(abspath $(BUILD))/stillheart"' -Itests/unit

$(BUILD)/tests/test_eval: $(BUILD)/tools/eval/tests/test_eval.o $(BUILD)/tests/unit/shell.o $(BUILD)/libphantom.a $(LIB) \
		$(EVAL_BIN) $(APP)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(BUILD)/libphantom.a $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) \
		$(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_eval

# The Table II figure (tools/eval/plot): built for make table2 and its test, not installed.
PLOT_BIN := $(BUILD)/tools/eval/table2-plot
$(BUILD)/tools/eval/plot/%.o: CFLAGS_ALL += -Itools/eval
$(PLOT_BIN): $(BUILD)/tools/eval/plot/table2_plot.o $(BUILD)/tools/eval/draw.o $(LIB)
	$(CC) $(LDFLAGS) $^ $(LDLIBS_ALL) -o $@

# The figures read back: the heatmap's size, scale and numbers; the plot's bars.
$(BUILD)/tools/eval/tests/test_figures.o: CFLAGS_ALL += -DEVAL_BIN='"$(abspath $(BUILD))/stillheart-eval"' \
	-DPLOT_BIN='"$(abspath $(PLOT_BIN))"' -Itools/eval -Itests/unit
$(BUILD)/tests/test_figures: $(BUILD)/tools/eval/tests/test_figures.o $(BUILD)/tools/eval/draw.o \
		$(BUILD)/tests/unit/shell.o $(LIB) $(EVAL_BIN) $(PLOT_BIN)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tools/eval/draw.o $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_figures

# The spectrum slope of --spectrum on images of known slope (closed form).
$(BUILD)/tools/eval/tests/test_spectrum.o: CFLAGS_ALL += -Itools/eval
$(BUILD)/tests/test_spectrum: $(BUILD)/tools/eval/tests/test_spectrum.o $(BUILD)/tools/eval/spectrum.o \
		$(BUILD)/libphantom.a $(LIB)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tools/eval/spectrum.o $(BUILD)/libphantom.a $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_spectrum

# The README's "Stabilize your own video" run as written (skipped without ffmpeg).
$(BUILD)/tools/eval/tests/test_readme_video.o: CFLAGS_ALL += -DREADME='"$(abspath README.md)"' \
	-DAPP_BIN='"$(abspath $(APP))"' -DEVAL_BIN='"$(abspath $(EVAL_BIN))"' \
	-DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"' -Itests/unit
$(BUILD)/tests/test_readme_video: $(BUILD)/tools/eval/tests/test_readme_video.o $(BUILD)/tests/unit/shell.o \
		$(LIB) $(APP) $(EVAL_BIN) $(BUILD)/stillheart-render
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_readme_video

# ---- Table II: both presets at the paper's length, one camera, every 2D method ----
# TABLE2_LANDMARKS=N adds the natural landmarks' rows (N asked, docs/landmarks.md): off by default,
# they more than double the run (a model per frame for every landmark row's warp and evaluation).
TABLE2_DIR ?= out/table2
TABLE2_LANDMARKS ?= 0
.PHONY: table2
table2: $(EVAL_BIN) $(PLOT_BIN) $(BUILD)/stillheart-render $(APP)
	@LANDMARKS=$(TABLE2_LANDMARKS) sh tools/eval/table2.sh $(BUILD) $(TABLE2_DIR)

# --landmarks on a rendered phantom with occlusions, judged against its truth; and
# `stillheart track --landmarks` through `stillheart warp`; the daemon's [track] landmarks against both.
$(BUILD)/tools/eval/tests/test_eval_landmarks.o: CFLAGS_ALL += -DEVAL_BIN='"$(abspath $(EVAL_BIN))"' \
	-DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"' -DAPP_BIN='"$(abspath $(APP))"' -Itests/unit
$(BUILD)/tests/test_eval_landmarks: $(BUILD)/tools/eval/tests/test_eval_landmarks.o $(BUILD)/tests/unit/shell.o \
		$(LIB) $(EVAL_BIN) $(BUILD)/stillheart-render $(APP)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_eval_landmarks

# carried frames (landmarks.h): four tags, two gone, the daemon and `stillheart track` against the truth
$(BUILD)/tools/eval/tests/test_carry.o: CFLAGS_ALL += -DEVAL_BIN='"$(abspath $(EVAL_BIN))"' \
	-DRENDER_BIN='"$(abspath $(BUILD))/stillheart-render"' -DAPP_BIN='"$(abspath $(APP))"' \
	-DSOURCE_DIR='"$(abspath .)"' -Itests/unit
$(BUILD)/tests/test_carry: $(BUILD)/tools/eval/tests/test_carry.o $(BUILD)/tests/unit/shell.o \
		$(LIB) $(EVAL_BIN) $(BUILD)/stillheart-render $(APP)
	@mkdir -p $(dir $@)
	$(CC) $(LDFLAGS) $< $(BUILD)/tests/unit/shell.o $(LIB) $(shell $(PKG_CONFIG) --libs cmocka) $(LDLIBS_ALL) -o $@

TOOL_TESTS += $(BUILD)/tests/test_carry

# ---- four tags through the product without and with carried frames (docs/landmarks.md) ----
CARRY_DIR ?= out/carry
.PHONY: carry-table
carry-table: $(EVAL_BIN) $(BUILD)/stillheart-render $(APP)
	@sh tools/eval/carry.sh $(BUILD) $(CARRY_DIR)

# ---- landmarks under blood that spreads slowly, against the truth (docs/landmarks.md) ----
BLOOD_DIR ?= out/blood
.PHONY: blood-table
blood-table: $(EVAL_BIN) $(BUILD)/stillheart-render
	@sh tools/eval/blood.sh $(BUILD) $(BLOOD_DIR)

# ---- natural landmarks on rendered phantoms against their truth (docs/landmarks.md) ----
LANDMARKS_DIR ?= out/landmarks
.PHONY: landmarks-table
landmarks-table: $(EVAL_BIN) $(BUILD)/stillheart-render
	@sh tools/eval/landmarks.sh $(BUILD) $(LANDMARKS_DIR)

# Landmarks in 3D on trinocular renders (tools/eval/landmarks3d.sh, docs/landmarks.md "In 3D"):
# track, the rows against the truth, warp3d and the geometric error; about 25 minutes.
LANDMARKS3D_DIR ?= out/landmarks3d
.PHONY: landmarks3d-table
landmarks3d-table: $(EVAL_BIN) $(BUILD)/stillheart-render $(APP)
	@sh tools/eval/landmarks3d.sh $(BUILD) $(LANDMARKS3D_DIR)