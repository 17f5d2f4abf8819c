/* The figures read back: stillheart-eval's heatmap (its size, its colour scale's ends against
 * matplotlib's viridis, its numbers against the font's bitmaps) and table2-plot's bars (heights
 * proportional to the e values written in its CSV). Tiny inputs: a 120x80 video of 3 frames. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval.h"
#include "shell.h"
#include "stillheart/png.h"

#if !defined(EVAL_BIN) || !defined(PLOT_BIN)
#error "EVAL_BIN and PLOT_BIN must name this build's stillheart-eval and table2-plot"
#endif

#define VW 120
#define VH 80

static char tmp[256];

static int setup(void **state)
{
    (void)state;
    snprintf(tmp, sizeof tmp, "/tmp/sh_test_figures_XXXXXX");
    return mkdtemp(tmp) ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    return test_run("rm -rf '%s'", tmp) == 0 ? 0 : -1;
}

static const char *at(const char *name)
{
    static char p[4][512];
    static int k;
    k = (k + 1) % 4;
    snprintf(p[k], sizeof p[k], "%s/%s", tmp, name);
    return p[k];
}

static sh_image read_png(const char *file)
{
    FILE *f = fopen(file, "rb");
    assert_non_null(f);
    sh_image img;
    assert_int_equal(sh_png_read(f, file, 0, &img), SH_OK);
    fclose(f);
    assert_int_equal(img.format, SH_PIX_RGB24);
    return img;
}

static const unsigned char *px(const sh_image *img, int x, int y)
{
    return img->plane[0].data + (size_t)y * img->plane[0].stride + 3 * (size_t)x;
}

static int is(const unsigned char *p, int r, int g, int b)
{
    return p[0] == r && p[1] == g && p[2] == b;
}

/* A mono video whose frames differ, and a hull (three markers) over its top half, so the colour
 * scale's strip goes along the bottom. */
static void write_inputs(void)
{
    FILE *f = fopen(at("v.y4m"), "wb");
    assert_non_null(f);
    fprintf(f, "YUV4MPEG2 W%d H%d F25:1 Ip A1:1 Cmono\n", VW, VH);
    for (int t = 0; t < 3; t++) {
        fputs("FRAME\n", f);
        for (int y = 0; y < VH; y++)
            for (int x = 0; x < VW; x++) fputc((x * 7 + y * 3 + t * 40 * (x > VW / 2)) & 255, f);
    }
    assert_int_equal(fclose(f), 0);
    f = fopen(at("p.csv"), "w");
    assert_non_null(f);
    fputs("frame,id,x,y\n", f);
    for (int t = 0; t < 3; t++)
        fprintf(f, "%d,0,5,2\n%d,1,115,2\n%d,2,60,40\n", t, t, t);
    assert_int_equal(fclose(f), 0);
}

static void heatmap(const char *png, const char *extra)
{
    assert_int_equal(test_run("'%s' --quiet --heatmap '%s' --heatmap-max 0.2 --contours 4 %s "
                              "--points '%s' '%s'", EVAL_BIN, png, extra, at("p.csv"), at("v.y4m")), 0);
}

static void test_heatmap_size(void **state)
{
    (void)state;
    write_inputs();
    static const struct { const char *opt; int w, h; } cases[] = {
        {"", VW, VH}, {"--heatmap-scale 2", 2 * VW, 2 * VH}, {"--heatmap-scale 0.5", VW / 2, VH / 2},
        {"--heatmap-scale=0.25", VW / 4, VH / 4},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        heatmap(at("h.png"), cases[i].opt);
        sh_image img = read_png(at("h.png"));
        assert_int_equal(img.width, cases[i].w);
        assert_int_equal(img.height, cases[i].h);
        sh_image_destroy(&img);
    }
    assert_int_equal(test_run("'%s' --heatmap-scale 0 --heatmap x.png --points '%s' '%s'", EVAL_BIN,
                              at("p.csv"), at("v.y4m")), 2);
    assert_non_null(strstr(test_out, "--heatmap-scale: '0' is not a number in"));
}

/* The bar: a row whose first and last pixels off the strip's background are viridis(0) and
 * viridis(1) (matplotlib: (0.267004, 0.004874, 0.329415) and (0.993248, 0.906157, 0.143936)),
 * across most of the width, in the bottom strip; nothing like it on top. */
static void test_heatmap_scale_bar_ends(void **state)
{
    (void)state;
    write_inputs();
    heatmap(at("h2.png"), "--heatmap-scale 2");
    sh_image img = read_png(at("h2.png"));
    int found = -1;
    for (int y = 0; y < img.height && found < 0; y++) {
        int x0 = 0, x1 = img.width - 1;
        while (x0 < x1 && is(px(&img, x0, y), 20, 20, 20)) x0++;
        while (x1 > x0 && is(px(&img, x1, y), 20, 20, 20)) x1--;
        if (is(px(&img, x0, y), 68, 1, 84) && is(px(&img, x1, y), 253, 231, 37) &&
            x1 - x0 > img.width * 9 / 10)
            found = y;
    }
    assert_true(found >= img.height - 30);
    sh_image_destroy(&img);
}

/* Where s drawn from the font's bitmaps (ink white, paper the strip's background) is in img. */
static int find_text(const sh_image *img, const char *s)
{
    int w = font_width(s, 1);
    for (int y = 0; y + FONT_H <= img->height; y++)
        for (int x = 0; x + w <= img->width; x++) {
            int ok = 1;
            for (int c = 0; s[c] && ok; c++) {
                const char(*g)[FONT_W + 1] = font_glyph(s[c]);
                assert_non_null(g);
                for (int r = 0; r < FONT_H && ok; r++)
                    for (int k = 0; k < FONT_W && ok; k++) {
                        const unsigned char *p = px(img, x + c * (FONT_W + 1) + k, y + r);
                        ok = g[r][k] == '#' ? is(p, 255, 255, 255) : is(p, 20, 20, 20);
                    }
            }
            if (ok) return 1;
        }
    return 0;
}

/* The numbers under the bar: 0, the four contour levels 0.2 k / 5 and the top, 0.2. */
static void test_heatmap_numbers(void **state)
{
    (void)state;
    write_inputs();
    heatmap(at("h2.png"), "--heatmap-scale 2");
    sh_image img = read_png(at("h2.png"));
    static const char *const labels[] = {"0", "0.04", "0.08", "0.12", "0.16", "0.2"};
    for (size_t i = 0; i < sizeof labels / sizeof labels[0]; i++) {
        if (!find_text(&img, labels[i])) {
            print_error("'%s' not found in the heatmap\n", labels[i]);
            fail();
        }
    }
    assert_false(find_text(&img, "0.25"));
    assert_false(find_text(&img, "0.3"));
    sh_image_destroy(&img);
}

/* Bars of a preset's colour (tab10, as --help says) that stand on the x axis, left to right:
 * heights into h (at most n). Returns how many. */
static int bars(const sh_image *img, const unsigned char rgb[3], int *h, int n)
{
    int base = -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            if (is(px(img, x, y), rgb[0], rgb[1], rgb[2]) && y > base) base = y;
    int count = 0;
    for (int x = 0; x < img->width;) {
        if (base < 0 || !is(px(img, x, base), rgb[0], rgb[1], rgb[2])) {
            x++;
            continue;
        }
        int x1 = x;
        while (x1 < img->width && is(px(img, x1, base), rgb[0], rgb[1], rgb[2])) x1++;
        int mid = (x + x1) / 2, y = base;
        while (y >= 0 && is(px(img, mid, y), rgb[0], rgb[1], rgb[2])) y--;
        assert_true(count < n);
        h[count++] = base - y;
        x = x1;
    }
    return count;
}

static void test_plot_bars(void **state)
{
    (void)state;
    FILE *f = fopen(at("t.csv"), "w");
    assert_non_null(f);
    fputs("preset,method,e\nexvivo,none,0.1\nexvivo,tps,0.05\nexvivo,bspline,0.2\n"
          "invivo,none,0.15\ninvivo,tps,n/a\ninvivo,bspline,0.025\n", f);
    assert_int_equal(fclose(f), 0);
    assert_int_equal(test_run("'%s' '%s' '%s'", PLOT_BIN, at("t.csv"), at("t.png")), 0);
    sh_image img = read_png(at("t.png"));
    static const unsigned char blue[3] = {0x1f, 0x77, 0xb4}, orange[3] = {0xff, 0x7f, 0x0e};
    int h[8];
    assert_int_equal(bars(&img, blue, h, 8), 3);
    /* 0.2 is the tallest; every other in proportion, to the pixel */
    assert_true(h[2] > 100);
    assert_true(abs(h[0] - (int)lrint(h[2] * 0.1 / 0.2)) <= 1);
    assert_true(abs(h[1] - (int)lrint(h[2] * 0.05 / 0.2)) <= 1);
    int g[8];
    assert_int_equal(bars(&img, orange, g, 8), 2);
    assert_true(abs(g[0] - (int)lrint(h[2] * 0.15 / 0.2)) <= 1);
    assert_true(abs(g[1] - (int)lrint(h[2] * 0.025 / 0.2)) <= 1);
    sh_image_destroy(&img);

    f = fopen(at("bad.csv"), "w");
    assert_non_null(f);
    fputs("preset,method,e\nexvivo,tps,-0.5\n", f);
    assert_int_equal(fclose(f), 0);
    assert_int_equal(test_run("'%s' '%s' '%s'", PLOT_BIN, at("bad.csv"), at("b.png")), 1);
    assert_non_null(strstr(test_out, "bad.csv:2: e '-0.5' is not a number >= 0"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_heatmap_size),
        cmocka_unit_test(test_heatmap_scale_bar_ends),
        cmocka_unit_test(test_heatmap_numbers),
        cmocka_unit_test(test_plot_bars),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
