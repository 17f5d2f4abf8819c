/* Outside the hull (sh_warp_outside): on a square hull whose inside is known in closed form, the
 * pixels outside are the current frame dimmed (halfway to black, computed here), the boundary
 * ones BT.601 cyan (converted here from RGB), and the inside ones the plain warp's, byte for byte,
 * in every format, both ranges and every chroma siting. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/warp.h"

enum { W = 64, H = 48 };

typedef struct {
    double x0, y0, x1, y1; /* the square: markers at its corners */
} square;

typedef struct {
    sh_interp *interp;
    sh_warp_model *model;
} built;

static built build_square(const square *s, double dx, double dy)
{
    double ref[8] = {s->x0, s->y0, s->x1, s->y0, s->x1, s->y1, s->x0, s->y1}, cur[8];
    for (int i = 0; i < 4; i++) {
        cur[2 * i] = ref[2 * i] + dx;
        cur[2 * i + 1] = ref[2 * i + 1] + dy;
    }
    built b = {0};
    sh_interp_params params;
    assert_int_equal(sh_interp_params_parse("affine", &params), SH_OK);
    assert_int_equal(sh_interp_create(&params, ref, 4, &b.interp), SH_OK);
    sh_warp_options opts;
    sh_warp_options_default(&opts);
    assert_int_equal(sh_warp_model_create(b.interp, ref, 4, W, H, &opts, &b.model), SH_OK);
    assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
    return b;
}

static void unbuild(built *b)
{
    sh_warp_model_destroy(b->model);
    sh_interp_destroy(b->interp);
}

static void fill_random(sh_image *img, unsigned seed)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width * sh_pixfmt_channels(img->format); x++) {
                seed = seed * 1103515245u + 12345u;
                img->plane[p].data[(size_t)y * img->plane[p].stride + x] = (uint8_t)(seed >> 16);
            }
}

/* Where pixel (x, y) of plane p sits in the full-resolution plane (the Y4M chroma sitings:
 * 420jpeg centred, 420mpeg2 left, 420paldv Cb on the line below, Cr on the line). */
static void position(sh_pixfmt f, sh_chroma_siting s, int p, int x, int y, double *X, double *Y)
{
    double scale = f == SH_PIX_I420 && p > 0 ? 2 : 1, ox = 0, oy = 0;
    if (scale == 2) {
        ox = s == SH_CHROMA_CENTER ? 0.5 : 0;
        oy = s == SH_CHROMA_CENTER || s == SH_CHROMA_LEFT ? 0.5 : p == 1 ? 1 : 0;
    }
    *X = scale * x + ox;
    *Y = scale * y + oy;
}

static int inside(const square *q, sh_pixfmt f, sh_chroma_siting s, int p, int x, int y)
{
    double X, Y;
    position(f, s, p, x, y, &X, &Y);
    return X >= q->x0 && X <= q->x1 && Y >= q->y0 && Y <= q->y1;
}

/* BT.601 cyan, RGB (0, 255, 255), in the plane's code values (ITU-R BT.601's matrix; limited:
 * Y 16..235, chroma 16..240). */
static double cyan(int p, int full)
{
    double r = 0, g = 1, b = 1;
    double y = 0.299 * r + 0.587 * g + 0.114 * b;
    double c = p == 1 ? (b - y) / 1.772 : (r - y) / 1.402;
    if (p == 0) return full ? 255 * y : 16 + 219 * y;
    return 128 + (full ? 255 : 224) * c;
}

/* Checks out (dimmed-raw) against plain (the black output) and raw over every pixel. */
static void check(const square *q, const sh_image *raw, const sh_image *plain, const sh_image *out, int full)
{
    sh_pixfmt f = raw->format;
    int ch = sh_pixfmt_channels(f), line = 0, dimmed = 0, kept = 0;
    for (int p = 0; p < raw->num_planes; p++) {
        int d = f == SH_PIX_I420 && p > 0 ? 1 : 2; /* two full-resolution pixels */
        double black = f == SH_PIX_RGB24 ? 0 : p > 0 ? 128 : full ? 0 : 16;
        const sh_plane *rp = &raw->plane[p], *pp = &plain->plane[p], *op = &out->plane[p];
        for (int y = 0; y < rp->height; y++)
            for (int x = 0; x < rp->width; x++) {
                int near = 0;
                for (int v = y - d; v <= y + d; v++)
                    for (int u = x - d; u <= x + d; u++)
                        if (u >= 0 && v >= 0 && u < rp->width && v < rp->height)
                            near |= inside(q, f, raw->siting, p, u, v);
                int in = inside(q, f, raw->siting, p, x, y);
                for (int c = 0; c < ch; c++) {
                    size_t at = (size_t)y * rp->stride + (size_t)(x * ch + c);
                    int o = op->data[at];
                    if (in) {
                        if (o != pp->data[at])
                            fail_msg("%s plane %d (%d,%d): inside %d, the warp's %d", sh_pixfmt_name(f), p, x, y, o, pp->data[at]);
                        kept++;
                    } else if (near) {
                        double want = f == SH_PIX_RGB24 ? (c ? 255 : 0) : cyan(p, full);
                        if (fabs(o - want) > 0.5 + 1e-9) /* the nearest code value; a half either way */
                            fail_msg("%s plane %d (%d,%d): boundary %d, cyan is %.3f", sh_pixfmt_name(f), p, x, y, o, want);
                        line++;
                    } else {
                        double want = floor(black + 0.5 * (rp->data[at] - black) + 0.5); /* halves up */
                        if (o != want)
                            fail_msg("%s plane %d (%d,%d): outside %d, raw %d dimmed is %.0f", sh_pixfmt_name(f), p, x,
                                     y, o, rp->data[at], want);
                        dimmed++;
                    }
                }
            }
    }
    assert_true(line > 0 && dimmed > 0 && kept > 0);
}

/* The frames of a case: the camera's (raw), the plain warp's and the one filled outside. */
typedef struct {
    sh_image raw, plain, out;
    sh_warp *warp;
    sh_warp_outside *outside;
    int full;
} fixture;

static void open_fixture(fixture *x, sh_pixfmt f, int full, sh_chroma_siting s, int threads)
{
    assert_int_equal(sh_image_create(&x->raw, f, W, H), SH_OK);
    assert_int_equal(sh_image_create(&x->plain, f, W, H), SH_OK);
    assert_int_equal(sh_image_create(&x->out, f, W, H), SH_OK);
    x->raw.siting = s;
    x->full = full;
    fill_random(&x->raw, (unsigned)(f * 7 + full * 3 + (int)s));
    assert_int_equal(sh_warp_create(threads, &x->warp), SH_OK);
    assert_int_equal(sh_warp_outside_create(f, W, H, full, &x->outside), SH_OK);
}

static void close_fixture(fixture *x)
{
    sh_warp_outside_destroy(x->outside);
    sh_warp_destroy(x->warp);
    sh_image_destroy(&x->raw);
    sh_image_destroy(&x->plain);
    sh_image_destroy(&x->out);
}

/* The warp of the camera's frame by b's model, plain and filled outside, checked against q. */
static void warp_and_check(fixture *x, const built *b, const square *q)
{
    assert_int_equal(sh_warp_apply(x->warp, b->model, &x->raw, &x->plain), SH_OK);
    assert_int_equal(sh_warp_apply(x->warp, b->model, &x->raw, &x->out), SH_OK);
    assert_int_equal(sh_warp_outside_apply(x->outside, b->model, &x->raw, &x->out), SH_OK);
    check(q, &x->raw, &x->plain, &x->out, x->full);
}

/* One format, range and siting: a square hull, its warp (a translation), the outside filled. */
static void run_case(sh_pixfmt f, int full, sh_chroma_siting s)
{
    const square q = {10, 8, 50, 38}, small = {21.5, 14.25, 40, 30};
    fixture x;
    open_fixture(&x, f, full, s, 1);
    built b = build_square(&q, 1.25, -0.5);
    warp_and_check(&x, &b, &q);
    /* the next frame, same model: the runs kept, the new frame's pixels dimmed */
    fill_random(&x.raw, 99u + (unsigned)f);
    warp_and_check(&x, &b, &q);
    /* another model with another hull: the runs made again for it */
    built c = build_square(&small, -0.75, 2);
    warp_and_check(&x, &c, &small);
    unbuild(&c);
    unbuild(&b);
    close_fixture(&x);
}

static void test_i420_every_siting(void **state)
{
    (void)state;
    for (int full = 0; full < 2; full++) {
        run_case(SH_PIX_I420, full, SH_CHROMA_CENTER);
        run_case(SH_PIX_I420, full, SH_CHROMA_LEFT);
        run_case(SH_PIX_I420, full, SH_CHROMA_PALDV);
    }
}

static void test_other_formats(void **state)
{
    (void)state;
    run_case(SH_PIX_RGB24, 0, SH_CHROMA_CENTER);
    run_case(SH_PIX_YUV444, 0, SH_CHROMA_CENTER);
    run_case(SH_PIX_YUV444, 1, SH_CHROMA_CENTER);
    run_case(SH_PIX_GRAY8, 0, SH_CHROMA_CENTER);
    run_case(SH_PIX_GRAY8, 1, SH_CHROMA_CENTER);
}

/* A hull past the frame's edges: nothing outside on those sides, no boundary drawn off the
 * frame; the warp on two threads. */
static void test_hull_beyond_frame(void **state)
{
    (void)state;
    const square q = {-20, 30, 90, 80};
    fixture x;
    open_fixture(&x, SH_PIX_I420, 0, SH_CHROMA_CENTER, 2);
    built b = build_square(&q, 0.5, 0.5);
    warp_and_check(&x, &b, &q);
    unbuild(&b);
    close_fixture(&x);
}

static void test_bad_input(void **state)
{
    (void)state;
    sh_warp_outside *o = NULL;
    assert_int_equal(sh_warp_outside_create(SH_PIX_I420, 0, H, 0, &o), SH_EINVAL);
    assert_int_equal(sh_warp_outside_create((sh_pixfmt)9, W, H, 0, &o), SH_EINVAL);
    assert_int_equal(sh_warp_outside_create(SH_PIX_I420, W, H, 0, NULL), SH_EINVAL);
    assert_int_equal(sh_warp_outside_create(SH_PIX_I420, W, H, 0, &o), SH_OK);
    const square q = {10, 8, 50, 38};
    built b = build_square(&q, 0, 0);
    sh_image small, rgb, frame;
    assert_int_equal(sh_image_create(&small, SH_PIX_I420, W / 2, H), SH_OK);
    assert_int_equal(sh_image_create(&rgb, SH_PIX_RGB24, W, H), SH_OK);
    assert_int_equal(sh_image_create(&frame, SH_PIX_I420, W, H), SH_OK);
    assert_int_equal(sh_warp_outside_apply(o, b.model, &small, &frame), SH_EINVAL);
    assert_int_equal(sh_warp_outside_apply(o, b.model, &frame, &rgb), SH_EINVAL);
    assert_int_equal(sh_warp_outside_apply(o, NULL, &frame, &frame), SH_EINVAL);
    assert_int_equal(sh_warp_outside_apply(o, b.model, &frame, &frame), SH_OK);
    unbuild(&b);
    sh_warp_outside_destroy(o);
    sh_warp_outside_destroy(NULL);
    sh_image_destroy(&small);
    sh_image_destroy(&rgb);
    sh_image_destroy(&frame);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_i420_every_siting),
        cmocka_unit_test(test_other_formats),
        cmocka_unit_test(test_hull_beyond_frame),
        cmocka_unit_test(test_bad_input),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
