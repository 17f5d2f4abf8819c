/* The picture stillheart-show puts on the monitor (src/screen), checked pixel by pixel against
 * closed forms written here: the letterbox rectangle, BT.601 conversion of the nearest frame
 * sample (floating point here, fixed point there: within 1), black bars, and the same bytes
 * drawn in bands; overlay off leaves
 * every picture pixel as it was; the status frame, the badge and the reason band where
 * screen.h puts them and in the status colours; glyphs against drawings of the 5x7 font made
 * here; NO SIGNAL's two lines where screen.h centres them. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/screen.h"

typedef struct {
    sh_screen_buffer b;
    uint32_t *mem;
} test_buf;

/* A buffer with 3 pixels of padding per row (stride != width*4), filled with a marker colour. */
static test_buf make_buf(int w, int h)
{
    test_buf t;
    t.b.width = w;
    t.b.height = h;
    t.b.stride = (w + 3) * 4;
    t.mem = malloc((size_t)t.b.stride * (size_t)h);
    assert_non_null(t.mem);
    for (size_t i = 0; i < (size_t)(w + 3) * (size_t)h; i++) t.mem[i] = 0x00123456u;
    t.b.pixels = t.mem;
    return t;
}

static uint32_t px(const test_buf *t, int x, int y) { return t->mem[(size_t)y * (size_t)(t->b.stride / 4) + (size_t)x]; }

static void test_layout(void **state)
{
    (void)state;
    struct { int fw, fh, sw, sh, x, y, w, h; } cases[] = {
        {320, 180, 640, 480, 0, 60, 640, 360},      /* 16:9 on 4:3: bars above and below */
        {640, 480, 1920, 1080, 240, 0, 1440, 1080}, /* 4:3 on 16:9: bars left and right */
        {1920, 1080, 1920, 1080, 0, 0, 1920, 1080}, /* the same size */
        {100, 100, 333, 200, 66, 0, 200, 200},      /* odd bar widths: (333 - 200) / 2 = 66 */
        {3, 1, 10, 10, 0, 3, 10, 3},                /* 10 / 3 = 3.33: rounded to 3 */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        sh_screen_layout l = sh_screen_layout_for(cases[i].fw, cases[i].fh, cases[i].sw, cases[i].sh);
        assert_int_equal(l.picture.x, cases[i].x);
        assert_int_equal(l.picture.y, cases[i].y);
        assert_int_equal(l.picture.width, cases[i].w);
        assert_int_equal(l.picture.height, cases[i].h);
    }
    sh_screen_layout l = sh_screen_layout_for(320, 180, 640, 480);
    assert_int_equal(l.border, 3); /* 480 / 160 */
    assert_int_equal(l.scale, 2);  /* 480 / 240 */
    assert_int_equal(l.badge.x, 0 + 3 + 4);
    assert_int_equal(l.badge.y, 60 + 3 + 4);
    assert_int_equal(l.badge.width, 10 * 6 * 2 + 4);
    assert_int_equal(l.badge.height, 7 * 2 + 8);
    l = sh_screen_layout_for(1920, 1080, 1920, 1080);
    assert_int_equal(l.border, 6);
    assert_int_equal(l.scale, 4);
    l = sh_screen_layout_for(0, 10, 640, 480);
    assert_int_equal(l.picture.width, 0);
}

static uint8_t clamp8(double v) { return v <= 0 ? 0 : v >= 255 ? 255 : (uint8_t)floor(v + 0.5); }

/* BT.601, as the standard writes it. */
static uint32_t ref_rgb(int Y, int U, int V, int full)
{
    double l = full ? Y : (Y - 16) * 255.0 / 219.0;
    double u = (U - 128) * (full ? 1.0 : 255.0 / 224.0), v = (V - 128) * (full ? 1.0 : 255.0 / 224.0);
    return (uint32_t)clamp8(l + 1.402 * v) << 16 | (uint32_t)clamp8(l - 0.344136 * u - 0.714136 * v) << 8 |
           clamp8(l + 1.772 * u);
}

static int near(uint32_t a, uint32_t b)
{
    for (int s = 0; s < 24; s += 8)
        if (abs((int)((a >> s) & 255) - (int)((b >> s) & 255)) > 1) return 0;
    return (a >> 24) == (b >> 24);
}

static void fill_frame(sh_image *f)
{
    for (int p = 0; p < f->num_planes; p++)
        for (int y = 0; y < f->plane[p].height; y++)
            for (int x = 0; x < f->plane[p].width * (f->format == SH_PIX_RGB24 ? 3 : 1); x++)
                f->plane[p].data[y * f->plane[p].stride + x] = (uint8_t)((x * 37 + y * 91 + p * 53) * 7 % 256);
}

/* Every pixel of the screen: bar black, picture the nearest frame sample converted. */
static void check_scaled(sh_pixfmt fmt, int fw, int fh, int sw, int sh, int full)
{
    sh_image f;
    assert_int_equal(sh_image_create(&f, fmt, fw, fh), SH_OK);
    fill_frame(&f);
    test_buf t = make_buf(sw, sh);
    sh_screen_layout l = sh_screen_layout_for(fw, fh, sw, sh);
    assert_int_equal(sh_screen_draw_frame(&t.b, &l, &f, full), SH_OK);
    const sh_screen_rect p = l.picture;
    int off = 0;
    for (int y = 0; y < sh; y++)
        for (int x = 0; x < sw; x++) {
            uint32_t got = px(&t, x, y), want;
            if (x < p.x || x >= p.x + p.width || y < p.y || y >= p.y + p.height) {
                want = 0;
            } else {
                int sx = (int)floor((x - p.x + 0.5) * fw / p.width), sy = (int)floor((y - p.y + 0.5) * fh / p.height);
                const uint8_t *y0 = f.plane[0].data + sy * f.plane[0].stride;
                if (fmt == SH_PIX_RGB24) want = (uint32_t)y0[3 * sx] << 16 | (uint32_t)y0[3 * sx + 1] << 8 | y0[3 * sx + 2];
                else if (fmt == SH_PIX_GRAY8) want = ref_rgb(y0[sx], 128, 128, full);
                else {
                    int cx = fmt == SH_PIX_I420 ? sx / 2 : sx, cy = fmt == SH_PIX_I420 ? sy / 2 : sy;
                    want = ref_rgb(y0[sx], f.plane[1].data[cy * f.plane[1].stride + cx],
                                   f.plane[2].data[cy * f.plane[2].stride + cx], full);
                }
            }
            if (fmt == SH_PIX_RGB24 || want == 0 ? got != want : !near(got, want)) {
                if (!off) print_error("%s %dx%d on %dx%d: (%d,%d) %06x, want %06x\n", sh_pixfmt_name(fmt), fw, fh,
                                      sw, sh, x, y, got, want);
                off++;
            }
        }
    assert_int_equal(off, 0);
    /* the padding after each row untouched */
    for (int y = 0; y < sh; y++) assert_int_equal(t.mem[(size_t)y * (size_t)(sw + 3) + (size_t)sw], 0x00123456u);
    /* bands that tile the screen (cuts in the bars, in the picture, on repeated rows; one empty,
     * one beyond the screen) make the same bytes, padding included */
    const int cuts[][2] = {{-5, 1}, {1, p.y / 2}, {p.y / 2, p.y + 1}, {p.y + 1, p.y + 1}, {p.y + 1, sh / 2 + 1},
                           {sh / 2 + 1, p.y + p.height - 1}, {p.y + p.height - 1, sh + 9}};
    test_buf u = make_buf(sw, sh);
    for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++)
        assert_int_equal(sh_screen_draw_frame_band(&u.b, &l, &f, full, cuts[k][0], cuts[k][1]), SH_OK);
    assert_memory_equal(u.mem, t.mem, (size_t)u.b.stride * (size_t)sh);
    free(u.mem);
    free(t.mem);
    sh_image_destroy(&f);
}

static void test_scale_convert(void **state)
{
    (void)state;
    check_scaled(SH_PIX_I420, 37, 23, 101, 77, 0); /* upscaled, odd sizes, limited range */
    check_scaled(SH_PIX_I420, 37, 23, 101, 77, 1); /* full range */
    check_scaled(SH_PIX_I420, 320, 180, 64, 48, 0); /* downscaled */
    check_scaled(SH_PIX_YUV444, 40, 30, 90, 50, 0);
    check_scaled(SH_PIX_GRAY8, 30, 40, 50, 90, 1);
    check_scaled(SH_PIX_RGB24, 17, 9, 40, 40, 0);
}

/* The painter's threads draw the bytes one thread draws (the whole draw is checked above), frame
 * after frame and size after size (its rows kept between frames and grown for a wider one), at
 * every thread count; counts outside 1..8 are refused. */
static void test_painter(void **state)
{
    (void)state;
    /* frames of three sizes in turn: as wide as the picture (no row), scaled up, and wider than
     * the screen (scaled down: the bands' rows grow for it) */
    enum { SIZES = 3 };
    const int fw[SIZES] = {203, 160, 400}, fh[SIZES] = {100, 90, 301};
    sh_image f[SIZES];
    sh_screen_layout l[SIZES];
    test_buf want[SIZES], got = make_buf(203, 151);
    for (int i = 0; i < SIZES; i++) {
        assert_int_equal(sh_image_create(&f[i], SH_PIX_I420, fw[i], fh[i]), SH_OK);
        fill_frame(&f[i]);
        want[i] = make_buf(203, 151);
        l[i] = sh_screen_layout_for(fw[i], fh[i], 203, 151);
        assert_int_equal(sh_screen_draw_frame(&want[i].b, &l[i], &f[i], 0), SH_OK);
    }
    for (int n = 1; n <= 8; n++) {
        sh_screen_painter *p;
        assert_int_equal(sh_screen_painter_create(n, &p), SH_OK);
        for (int round = 0; round < 3 * SIZES; round++) {
            const int i = round % SIZES;
            memset(got.mem, round, (size_t)got.b.stride * 151);
            for (int y = 0; y < 151; y++) /* the padding as make_buf leaves it: never drawn */
                for (int x = 203; x < 206; x++) got.mem[(size_t)y * (203 + 3) + (size_t)x] = 0x00123456u;
            assert_int_equal(sh_screen_painter_draw(p, &got.b, &l[i], &f[i], 0), SH_OK);
            assert_memory_equal(got.mem, want[i].mem, (size_t)got.b.stride * 151);
        }
        sh_screen_painter_destroy(p);
    }
    sh_screen_painter *p;
    assert_int_equal(sh_screen_painter_create(0, &p), SH_EINVAL);
    assert_int_equal(sh_screen_painter_create(9, &p), SH_EINVAL);
    /* a refusal of the frame comes back from the threads' round too */
    assert_int_equal(sh_screen_painter_create(3, &p), SH_OK);
    sh_image rgba = f[1];
    rgba.format = (sh_pixfmt)99;
    assert_int_equal(sh_screen_painter_draw(p, &got.b, &l[1], &rgba, 0), SH_EINVAL);
    sh_screen_painter_destroy(p);
    for (int i = 0; i < SIZES; i++) {
        free(want[i].mem);
        sh_image_destroy(&f[i]);
    }
    free(got.mem);
}

static void test_refusals(void **state)
{
    (void)state;
    sh_image f;
    assert_int_equal(sh_image_create(&f, SH_PIX_I420, 16, 16), SH_OK);
    test_buf t = make_buf(32, 32);
    sh_screen_layout l = sh_screen_layout_for(16, 16, 64, 64); /* a layout for a larger screen */
    assert_int_equal(sh_screen_draw_frame(&t.b, &l, &f, 0), SH_EINVAL);
    sh_screen_overlay o;
    assert_true(sh_screen_overlay_parse("off", &o) && o == SH_SCREEN_OVERLAY_OFF);
    assert_true(sh_screen_overlay_parse("minimal", &o) && o == SH_SCREEN_OVERLAY_MINIMAL);
    assert_true(sh_screen_overlay_parse("full", &o) && o == SH_SCREEN_OVERLAY_FULL);
    assert_false(sh_screen_overlay_parse("Full", &o));
    assert_false(sh_screen_overlay_parse("", &o));
    free(t.mem);
    sh_image_destroy(&f);
}

/* A frame on a 640x480 screen, its overlay drawn over it; the screen before the overlay in *before. */
static test_buf framed(sh_screen_overlay ov, uint32_t status, const char *reason, test_buf *before, sh_screen_layout *l)
{
    sh_image f;
    assert_int_equal(sh_image_create(&f, SH_PIX_I420, 320, 180), SH_OK);
    fill_frame(&f);
    test_buf t = make_buf(640, 480);
    *before = make_buf(640, 480);
    *l = sh_screen_layout_for(320, 180, 640, 480);
    assert_int_equal(sh_screen_draw_frame(&t.b, l, &f, 0), SH_OK);
    memcpy(before->mem, t.mem, (size_t)t.b.stride * 480);
    sh_screen_draw_status(&t.b, l, ov, status, reason, 44);
    sh_image_destroy(&f);
    return t;
}

static void test_overlay_off(void **state)
{
    (void)state;
    test_buf before;
    sh_screen_layout l;
    test_buf t = framed(SH_SCREEN_OVERLAY_OFF, 0, "markers lost: 5 of 16 visible", &before, &l);
    assert_memory_equal(t.mem, before.mem, (size_t)t.b.stride * 480);
    free(t.mem);
    free(before.mem);
}

static void test_overlay_minimal(void **state)
{
    (void)state;
    test_buf before;
    sh_screen_layout l;
    test_buf t = framed(SH_SCREEN_OVERLAY_MINIMAL, 2, "short dropout", &before, &l);
    /* a 3-pixel amber band inside the picture's edge (y 60..419), all else as before */
    for (int y = 0; y < 480; y++)
        for (int x = 0; x < 640; x++) {
            int in = y >= 60 && y < 420;
            int edge = in && (x < 3 || x >= 637 || y < 63 || y >= 417);
            assert_int_equal(px(&t, x, y), edge ? 0x00ffb000u : px(&before, x, y));
        }
    free(t.mem);
    free(before.mem);
}

static void test_overlay_full(void **state)
{
    (void)state;
    test_buf before;
    sh_screen_layout l;
    const char *reason = "markers lost: 5 of 16 visible";
    test_buf t = framed(SH_SCREEN_OVERLAY_FULL, 0, reason, &before, &l);
    /* badge: x 7..130, y 67..88; reason band: from x 3, 22 rows ending at the border (y 416),
     * 29 cells of 12 plus padding 8 less the last blank column 2 */
    int bx0 = 7, by0 = 67, bx1 = 7 + 124, by1 = 67 + 22;
    int rx0 = 3, ry0 = 417 - 22, rx1 = 3 + 29 * 12 + 8 - 2, ry1 = 417;
    int badge_black = 0, band_white = 0;
    for (int y = 60; y < 420; y++)
        for (int x = 0; x < 640; x++) {
            uint32_t p = px(&t, x, y);
            if (x < 3 || x >= 637 || y < 63 || y >= 417) assert_int_equal(p, 0x00e00000u);
            else if (x >= bx0 && x < bx1 && y >= by0 && y < by1) {
                assert_true(p == 0x00e00000u || p == 0);
                badge_black += p == 0;
            } else if (x >= rx0 && x < rx1 && y >= ry0 && y < ry1) {
                assert_true(p == 0x00ffffffu || p == 0);
                band_white += p == 0x00ffffffu;
            } else assert_int_equal(p, px(&before, x, y));
        }
    /* "RAW": R 18 + A 18 + W 17 set pixels in test_glyphs' drawings, 4 screen pixels each */
    assert_int_equal(badge_black, (18 + 18 + 17) * 4);
    assert_true(band_white > 0);
    free(t.mem);
    free(before.mem);
}

/* The glyph drawn at scale 1 in a 6x8 cell equals the drawing. */
static void check_glyph(char c, const char *drawing)
{
    test_buf t = make_buf(6, 8);
    sh_screen_fill(&t.b, (sh_screen_rect){0, 0, 6, 8}, 0);
    char s[2] = {c, 0};
    assert_int_equal(sh_screen_draw_text(&t.b, 0, 0, 1, 0x00ffffffu, s, 1), 6);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 6; x++) {
            int set = y < 7 && x < 5 && drawing[y * 5 + x] == '#';
            if (px(&t, x, y) != (set ? 0x00ffffffu : 0u)) fail_msg("glyph '%c' (%d,%d)", c, x, y);
        }
    free(t.mem);
}

static void test_glyphs(void **state)
{
    (void)state;
    check_glyph('R', "####." "#...#" "#...#" "####." "#.#.." "#..#." "#...#");
    check_glyph('A', ".###." "#...#" "#...#" "#####" "#...#" "#...#" "#...#");
    check_glyph('W', "#...#" "#...#" "#...#" "#.#.#" "#.#.#" "#.#.#" ".#.#.");
    check_glyph('a', ".###." "#...#" "#...#" "#####" "#...#" "#...#" "#...#"); /* as upper case */
    check_glyph('5', "#####" "#...." "####." "....#" "....#" "#...#" ".###.");
    check_glyph(':', "....." ".##.." ".##.." "....." ".##.." ".##.." ".....");
    check_glyph('\x7f', ".###." "#...#" "....#" "...#." "..#.." "....." "..#.."); /* not in the font: '?' */
    check_glyph((char)0xc3, ".###." "#...#" "....#" "...#." "..#.." "....." "..#..");
    /* scale 2: each font pixel a 2x2 block; the text clipped at the buffer's edge */
    test_buf t = make_buf(10, 16);
    sh_screen_fill(&t.b, (sh_screen_rect){0, 0, 10, 16}, 0);
    assert_int_equal(sh_screen_draw_text(&t.b, 0, 0, 2, 1, "T", 8), 12);
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 10; x++)
            assert_int_equal(px(&t, x, y), (uint32_t)((y < 2) || (y < 14 && x >= 4 && x < 6)));
    free(t.mem);
}

static void test_no_signal(void **state)
{
    (void)state;
    /* the whole screen: black, and white only where the two lines are (centred on their glyphs) */
    test_buf t = make_buf(640, 480);
    sh_screen_draw_no_signal(&t.b, 3.7);
    test_buf want = make_buf(640, 480);
    sh_screen_fill(&want.b, (sh_screen_rect){0, 0, 640, 480}, 0);
    /* "NO SIGNAL" 9 cells of 24 at scale 4, less one blank column of 4: 212 wide, rows 208..; the
     * second line "LAST FRAME 3 S AGO" 18 cells of 12, less 2: 214 wide, rows 244.. */
    sh_screen_draw_text(&want.b, (640 - 212) / 2, 240 - 32, 4, 0x00ffffffu, "NO SIGNAL", 64);
    sh_screen_draw_text(&want.b, (640 - 214) / 2, 240 + 4, 2, 0x00ffffffu, "LAST FRAME 3 S AGO", 64);
    assert_memory_equal(t.mem, want.mem, (size_t)t.b.stride * 480);
    sh_screen_draw_no_signal(&t.b, -1);
    sh_screen_fill(&want.b, (sh_screen_rect){0, 0, 640, 480}, 0);
    sh_screen_draw_text(&want.b, (640 - 212) / 2, 240 - 32, 4, 0x00ffffffu, "NO SIGNAL", 64);
    sh_screen_draw_text(&want.b, (640 - (12 * 12 - 2)) / 2, 240 + 4, 2, 0x00ffffffu, "NO FRAME YET", 64);
    assert_memory_equal(t.mem, want.mem, (size_t)t.b.stride * 480);
    free(t.mem);
    free(want.mem);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_layout),       cmocka_unit_test(test_scale_convert),
        cmocka_unit_test(test_refusals),     cmocka_unit_test(test_painter),     cmocka_unit_test(test_overlay_off),
        cmocka_unit_test(test_overlay_minimal), cmocka_unit_test(test_overlay_full),
        cmocka_unit_test(test_glyphs),       cmocka_unit_test(test_no_signal),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
