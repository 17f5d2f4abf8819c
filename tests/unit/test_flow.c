/* src/flow against answers known without it: a texture moved by a known sub-pixel shift, a
 * known large shift (which only the pyramid can follow), the synthetic sequence's exact
 * deformation (tools/synth), a checkerboard's corners, and what must be refused. OpenCV's own
 * tracker, the oracle, is compared in tests/oracle/test_flow_opencv.cpp (host builds). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/flow.h"
#include "synth.h"

/* The synthetic texture moved by (dx, dy): what sits at (x, y) in the texture sits at
 * (x + dx, y + dy) in the image. */
static void render_shifted(sh_image *img, double dx, double dy)
{
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            double v = synth_texture(x - dx, y - dy, 0);
            img->plane[0].data[(size_t)y * img->plane[0].stride + x] = (uint8_t)lrint(v);
        }
}

typedef struct {
    sh_flow_params prm;
    sh_flow_pyramid *a, *b;
} pair;

static void pair_make(pair *p, const sh_image *fa, const sh_image *fb, int levels)
{
    sh_flow_params_default(&p->prm);
    p->prm.levels = levels;
    assert_int_equal(sh_flow_pyramid_create(fa->width, fa->height, &p->prm, &p->a), SH_OK);
    assert_int_equal(sh_flow_pyramid_create(fa->width, fa->height, &p->prm, &p->b), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(p->a, &fa->plane[0], 1), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(p->b, &fb->plane[0], 0), SH_OK);
}

static void pair_free(pair *p)
{
    sh_flow_pyramid_destroy(p->a);
    sh_flow_pyramid_destroy(p->b);
}

/* A grid of points well inside a w x h frame: n = cols * rows. */
static int grid(float *xy, int w, int h, int cols, int rows)
{
    int n = 0;
    for (int r = 0; r < rows; r++)
        for (int c = 0; c < cols; c++) {
            xy[2 * n] = (float)(60 + (w - 120) * c / (cols - 1)) + 0.3f;
            xy[2 * n + 1] = (float)(60 + (h - 120) * r / (rows - 1)) + 0.7f;
            n++;
        }
    return n;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The median and largest distance of the followed points from p + (dx, dy); -1 and -1 when one
 * was lost. */
static void shift_error(const pair *p, int n, const float *xy, const float *guess, double dx,
                        double dy, double *median, double *worst)
{
    float out[2 * 64], err[64];
    uint8_t st[64];
    double e[64];
    assert_int_equal(sh_flow_track(&p->prm, p->a, p->b, n, xy, guess, out, st, err), SH_OK);
    *median = *worst = -1;
    for (int i = 0; i < n; i++) {
        if (st[i] != SH_FLOW_OK) return;
        e[i] = hypot(out[2 * i] - (xy[2 * i] + dx), out[2 * i + 1] - (xy[2 * i + 1] + dy));
    }
    qsort(e, (size_t)n, sizeof *e, by_value);
    *median = e[n / 2];
    *worst = e[n - 1];
}

/* A sub-pixel shift, recovered at every point of a grid. The bound: 8-bit rounding of a texture
 * whose gradients are a few grey levels per pixel, over a 21x21 window, moves the solution by
 * thousandths of a pixel; bilinear sampling of its shortest (15 px) waves by about 1/100. */
static void test_subpixel_shift(void **state)
{
    (void)state;
    sh_image fa, fb;
    assert_int_equal(sh_image_create(&fa, SH_PIX_GRAY8, 320, 240), SH_OK);
    assert_int_equal(sh_image_create(&fb, SH_PIX_GRAY8, 320, 240), SH_OK);
    render_shifted(&fa, 0, 0);
    render_shifted(&fb, 0.37, -0.61);
    pair p;
    pair_make(&p, &fa, &fb, 3);
    float xy[2 * 64];
    int n = grid(xy, 320, 240, 6, 5);
    double median, worst;
    shift_error(&p, n, xy, NULL, 0.37, -0.61, &median, &worst);
    print_message("sub-pixel shift: error median %.4f px, largest %.4f px over %d points\n",
                  median, worst, n);
    assert_true(median >= 0 && median < 0.05);
    assert_true(worst < 0.2);
    pair_free(&p);
    sh_image_destroy(&fa);
    sh_image_destroy(&fb);
}

/* A shift of 16 px, past a 21 px window's reach and the 15 px waves' period: the pyramid
 * follows it; the base level alone must not (it locks onto a wrong wave or loses the point),
 * which shows the levels are used. A guess within a few pixels lets even the base level find it
 * (the heartbeat model's prediction, OpenCV's OPTFLOW_USE_INITIAL_FLOW). */
static void test_large_shift_needs_levels_or_guess(void **state)
{
    (void)state;
    const double dx = 27.4, dy = -19.2;
    sh_image fa, fb;
    assert_int_equal(sh_image_create(&fa, SH_PIX_GRAY8, 320, 240), SH_OK);
    assert_int_equal(sh_image_create(&fb, SH_PIX_GRAY8, 320, 240), SH_OK);
    render_shifted(&fa, 0, 0);
    render_shifted(&fb, dx, dy);
    float xy[2 * 64], guess[2 * 64];
    int n = grid(xy, 320, 240, 5, 4);
    for (int i = 0; i < n; i++) {
        guess[2 * i] = xy[2 * i] + (float)dx + 1.8f;
        guess[2 * i + 1] = xy[2 * i + 1] + (float)dy - 1.5f;
    }
    pair p;
    pair_make(&p, &fa, &fb, 3);
    double pyr, pyr_worst, base, base_worst, guided, guided_worst;
    shift_error(&p, n, xy, NULL, dx, dy, &pyr, &pyr_worst);
    pair_free(&p);
    pair_make(&p, &fa, &fb, 0);
    shift_error(&p, n, xy, NULL, dx, dy, &base, &base_worst);
    shift_error(&p, n, xy, guess, dx, dy, &guided, &guided_worst);
    pair_free(&p);
    print_message("%.0f px shift, error median / largest: pyramid %.4f / %.4f px, base level "
                  "%.3f / %.3f px (-1: lost), base level with a guess %.4f / %.4f px\n",
                  hypot(dx, dy), pyr, pyr_worst, base, base_worst, guided, guided_worst);
    assert_true(pyr >= 0 && pyr < 0.05 && pyr_worst < 0.2);
    assert_true(base < 0 || base_worst > 1.0);
    assert_true(guided >= 0 && guided < 0.05 && guided_worst < 0.2);
    sh_image_destroy(&fa);
    sh_image_destroy(&fb);
}

/* How far the displacement anywhere in p's window strays from p's own: a translation fitted to
 * the window (what Lucas-Kanade estimates: the window's displacements averaged, weighted by
 * its gradients) cannot stray from p's displacement by more. */
static double window_spread(const synth_motion *m, double t, double px, double py, int win)
{
    double fx, fy, worst = 0;
    synth_forward(m, t, px, py, &fx, &fy);
    const double h = (win - 1) / 2.0;
    for (int j = 0; j <= 8; j++)
        for (int i = 0; i <= 8; i++) {
            double qx = px - h + 2 * h * i / 8, qy = py - h + 2 * h * j / 8, gx, gy;
            synth_forward(m, t, qx, qy, &gx, &gy);
            double d = hypot((gx - qx) - (fx - px), (gy - qy) - (fy - py));
            if (d > worst) worst = d;
        }
    return worst;
}

/* Corners of the synthetic sequence's reference followed into a deformed frame, against the
 * deformation's exact value (synth_forward). Within a 21 px window the deformation is not a
 * shift (bulge, twist, rotation: strains of a few percent), so each point may be off by as much
 * as its window's displacements differ, plus the 0.05 px of a pure shift. */
static void test_deformation_against_truth(void **state)
{
    (void)state;
    synth_motion m = {320, 240, 6.0};
    sh_image f0, f1;
    assert_int_equal(sh_image_create(&f0, SH_PIX_GRAY8, 320, 240), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, 320, 240), SH_OK);
    synth_render(&m, 0.0, &f0);
    synth_render(&m, 0.2, &f1);
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    cp.max_points = 150;
    float xy[2 * 150], out[2 * 150], err[150];
    uint8_t st[150];
    int n;
    assert_int_equal(sh_flow_corners(&f0.plane[0], NULL, &cp, xy, &n), SH_OK);
    assert_true(n >= 100);
    pair p;
    pair_make(&p, &f0, &f1, 3);
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, n, xy, NULL, out, st, err), SH_OK);
    double e[150], worst_excess = -1e9;
    int kept = 0, inner = 0;
    for (int i = 0; i < n; i++) {
        double fx, fy;
        synth_forward(&m, 0.2, xy[2 * i], xy[2 * i + 1], &fx, &fy);
        /* a window that reaches past the frame sees the mirrored border, not the texture */
        if (fx < 11 || fy < 11 || fx > 320 - 12 || fy > 240 - 12) continue;
        inner++;
        if (st[i] != SH_FLOW_OK) continue;
        e[kept] = hypot(out[2 * i] - fx, out[2 * i + 1] - fy);
        double excess = e[kept] - window_spread(&m, 0.2, xy[2 * i], xy[2 * i + 1], p.prm.win);
        if (excess > worst_excess) worst_excess = excess;
        kept++;
    }
    qsort(e, (size_t)kept, sizeof *e, by_value);
    print_message("deformation: %d of %d inner points kept, error median %.4f px, largest %.4f "
                  "px, largest beyond its window's spread of displacements %.4f px\n",
                  kept, inner, e[kept / 2], e[kept - 1], worst_excess);
    assert_int_equal(kept, inner);
    assert_true(worst_excess < 0.05);
    pair_free(&p);
    sh_image_destroy(&f0);
    sh_image_destroy(&f1);
}

/* What cannot be followed is said so, never given a position as if it were followed. */
static void test_flat_outside_and_bad_points(void **state)
{
    (void)state;
    sh_image flat, tex;
    assert_int_equal(sh_image_create(&flat, SH_PIX_GRAY8, 160, 120), SH_OK);
    assert_int_equal(sh_image_create(&tex, SH_PIX_GRAY8, 160, 120), SH_OK);
    for (int y = 0; y < 120; y++) memset(flat.plane[0].data + (size_t)y * flat.plane[0].stride, 90, 160);
    render_shifted(&tex, 0, 0);
    pair p;
    pair_make(&p, &flat, &flat, 2);
    float xy[2] = {80, 60}, out[2 * 4];
    uint8_t st[4];
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, 1, xy, NULL, out, st, NULL), SH_OK);
    assert_int_equal(st[0], SH_FLOW_FLAT);
    pair_free(&p);
    pair_make(&p, &tex, &tex, 2);
    const float bad[2 * 4] = {-40, 60, 80, 1e30f, NAN, 60, 80, 60};
    float guess[2 * 4] = {-40, 60, 80, 60, 80, 60, 80, INFINITY};
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, 4, bad, guess, out, st, NULL), SH_OK);
    for (int i = 0; i < 4; i++) assert_int_equal(st[i], SH_FLOW_OUTSIDE);
    /* the same texture: every point stays where it is */
    const float here[2] = {57.5f, 33.25f};
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, 1, here, NULL, out, st, NULL), SH_OK);
    assert_int_equal(st[0], SH_FLOW_OK);
    assert_true(fabsf(out[0] - here[0]) < 1e-3f && fabsf(out[1] - here[1]) < 1e-3f);
    pair_free(&p);
    sh_image_destroy(&flat);
    sh_image_destroy(&tex);
}

/* Whether two floats are the same bits. */
static int same_bits(float a, float b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

/* A pyramid built only for a box of points (sh_flow_pyramid_build_box) gives every point either
 * the result of the whole frame's pyramid, bit for bit, or SH_FLOW_UNBUILT; a search that stays
 * near the box gets its result; the frame is read only in sh_flow_pyramid_box_part's rectangle
 * (the rest of it garbage here); and what an earlier build of another frame left in the pyramid
 * is never read. Boxes in the middle, touching the top-left and bottom-right edges, and as a
 * previous (gradients: the backward search's) and a next frame. */
static void test_box_build_same_as_whole(void **state)
{
    (void)state;
    enum { FW = 320, FH = 240, GRID = 8, N = GRID * GRID };
    const double dx = 2.3, dy = -1.4;
    sh_image f0, f1, junk, other;
    assert_int_equal(sh_image_create(&f0, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&junk, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&other, SH_PIX_GRAY8, FW, FH), SH_OK);
    render_shifted(&f0, 0, 0);
    render_shifted(&f1, dx, dy);
    render_shifted(&other, -7, 5);
    float xy[2 * N], guess[2 * N], ref_out[2 * N], out[2 * N], ref_err[N], err[N];
    uint8_t ref_st[N], st[N];
    for (int i = 0; i < N; i++) {
        xy[2 * i] = 4.0f + (float)(FW - 8) * (float)(i % GRID) / (GRID - 1) + 0.25f;
        xy[2 * i + 1] = 4.0f + (float)(FH - 8) * (float)(i / GRID) / (GRID - 1) + 0.5f;
        guess[2 * i] = xy[2 * i] + (float)dx;
        guess[2 * i + 1] = xy[2 * i + 1] + (float)dy;
    }
    const float boxes[4][4] = {{100, 80, 220, 160}, {-30, -30, 60, 50}, {250, 170, 400, 300}, {150, 110, 150, 110}};
    for (int role = 0; role < 2; role++) /* 0: the box-built pyramid is the next frame; 1: the previous */
        for (int b = 0; b < 4; b++) {
            const float *box = boxes[b];
            pair p;
            pair_make(&p, &f0, &f1, 3);
            /* the whole frame's answer: forward (role 0), or backward from f1 to f0 (role 1) */
            sh_flow_pyramid *whole_b = NULL, *whole_a = NULL;
            assert_int_equal(sh_flow_pyramid_create(FW, FH, &p.prm, &whole_b), SH_OK);
            assert_int_equal(sh_flow_pyramid_build(whole_b, &f1.plane[0], 1), SH_OK);
            assert_int_equal(sh_flow_pyramid_create(FW, FH, &p.prm, &whole_a), SH_OK);
            assert_int_equal(sh_flow_pyramid_build(whole_a, &f0.plane[0], 0), SH_OK);
            const float *from = role ? guess : xy, *to = role ? xy : guess;
            if (role)
                assert_int_equal(sh_flow_track(&p.prm, whole_b, whole_a, N, from, to, ref_out, ref_st, ref_err), SH_OK);
            else
                assert_int_equal(sh_flow_track(&p.prm, p.a, whole_b, N, from, to, ref_out, ref_st, ref_err), SH_OK);
            /* f1 with garbage outside the part the box reads, into a pyramid that held another frame */
            int part[4];
            assert_int_equal(sh_flow_pyramid_box_part(p.b, box, role, part), SH_OK);
            assert_true(part[0] >= 0 && part[1] >= 0 && part[2] <= FW && part[3] <= FH);
            for (int y = 0; y < FH; y++)
                for (int x = 0; x < FW; x++) {
                    int in = x >= part[0] && x < part[2] && y >= part[1] && y < part[3];
                    junk.plane[0].data[(size_t)y * junk.plane[0].stride + x] =
                        in ? f1.plane[0].data[(size_t)y * f1.plane[0].stride + x] : (uint8_t)((x * 37 + y * 91) & 255);
                }
            assert_int_equal(sh_flow_pyramid_build(p.b, &other.plane[0], 1), SH_OK);
            assert_int_equal(sh_flow_pyramid_build_box(p.b, &junk.plane[0], role, box), SH_OK);
            if (role)
                assert_int_equal(sh_flow_track(&p.prm, p.b, whole_a, N, from, to, out, st, err), SH_OK);
            else
                assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, N, from, to, out, st, err), SH_OK);
            int kept = 0;
            for (int i = 0; i < N; i++) {
                const float *s = from + 2 * i;
                /* a search from inside the box grown by a window and the shift stays built */
                const float r = 3.0f;
                int near = s[0] >= box[0] + r && s[0] <= box[2] - r && s[1] >= box[1] + r && s[1] <= box[3] - r;
                if (st[i] == SH_FLOW_UNBUILT) {
                    assert_false(near);
                    continue;
                }
                kept++;
                assert_int_equal(st[i], ref_st[i]);
                assert_true(same_bits(out[2 * i], ref_out[2 * i]) && same_bits(out[2 * i + 1], ref_out[2 * i + 1]));
                assert_true(same_bits(err[i], ref_err[i]));
            }
            /* the searches far from the small boxes could not be done (the middle one's part is
             * the whole of this small frame: its coarsest level's windows reach that far) */
            assert_true(kept >= 1);
            if (b > 0) assert_true(kept < N);
            sh_flow_pyramid_destroy(whole_a);
            sh_flow_pyramid_destroy(whole_b);
            pair_free(&p);
        }
    float bad[4] = {10, 10, 5, 20};
    pair p;
    pair_make(&p, &f0, &f1, 3);
    int part[4];
    assert_int_equal(sh_flow_pyramid_build_box(p.b, &f1.plane[0], 0, bad), SH_EINVAL);
    bad[2] = NAN;
    assert_int_equal(sh_flow_pyramid_box_part(p.b, bad, 0, part), SH_EINVAL);
    pair_free(&p);
    sh_image_destroy(&f0);
    sh_image_destroy(&f1);
    sh_image_destroy(&junk);
    sh_image_destroy(&other);
}

/* sh_flow_pyramid_update_box: a pyramid built whole from one frame, then updated for a box from
 * a frame that differs from it only inside the box (a patch of other texture), tracks every point,
 * near the box and far from it, forward (as the next frame) and backward (as the previous one,
 * with its gradients), bit for bit as the pyramid built whole from the second frame; the windows
 * made from it and then refreshed (sh_flow_windows_refresh) track as windows made anew. A box
 * reaching past what a pyramid built for a smaller box holds is refused. */
static void test_update_box_same_as_whole(void **state)
{
    (void)state;
    enum { FW = 320, FH = 240, GRID = 9, N = GRID * GRID };
    sh_image f0, f1, g;
    assert_int_equal(sh_image_create(&f0, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&g, SH_PIX_GRAY8, FW, FH), SH_OK);
    render_shifted(&f0, 0, 0);
    render_shifted(&f1, 1.6, -0.9);
    render_shifted(&g, 0, 0);
    const float boxes[3][4] = {{120, 90, 200, 150}, {-10, -10, 40, 30}, {280, 200, 330, 250}};
    for (int b = 0; b < 3; b++) {
        const float *box = boxes[b];
        /* g: f0 with other texture inside the box (f0 shifted by 5 px there) */
        for (int y = 0; y < FH; y++)
            for (int x = 0; x < FW; x++) {
                int in = x >= box[0] && x <= box[2] && y >= box[1] && y <= box[3];
                g.plane[0].data[(size_t)y * g.plane[0].stride + x] =
                    in ? f0.plane[0].data[(size_t)y * f0.plane[0].stride + (x + 5 < FW ? x + 5 : x)]
                       : f0.plane[0].data[(size_t)y * f0.plane[0].stride + x];
            }
        sh_flow_params prm;
        sh_flow_params_default(&prm);
        prm.levels = 2;
        sh_flow_pyramid *upd, *whole, *next;
        assert_int_equal(sh_flow_pyramid_create(FW, FH, &prm, &upd), SH_OK);
        assert_int_equal(sh_flow_pyramid_create(FW, FH, &prm, &whole), SH_OK);
        assert_int_equal(sh_flow_pyramid_create(FW, FH, &prm, &next), SH_OK);
        assert_int_equal(sh_flow_pyramid_build(upd, &f0.plane[0], 1), SH_OK);
        assert_int_equal(sh_flow_pyramid_build(whole, &g.plane[0], 1), SH_OK);
        assert_int_equal(sh_flow_pyramid_build(next, &f1.plane[0], 1), SH_OK);
        float xy[2 * N], guess[2 * N], a[2 * N], c[2 * N], ea[N], ec[N];
        uint8_t sa[N], sc[N];
        for (int i = 0; i < N; i++) {
            xy[2 * i] = 2.0f + (float)(FW - 4) * (float)(i % GRID) / (GRID - 1) + 0.25f;
            xy[2 * i + 1] = 2.0f + (float)(FH - 4) * (float)(i / GRID) / (GRID - 1) + 0.5f;
            guess[2 * i] = xy[2 * i] + 1.6f, guess[2 * i + 1] = xy[2 * i + 1] - 0.9f;
        }
        sh_flow_windows *w_upd = NULL, *w_whole = NULL;
        assert_int_equal(sh_flow_windows_create(&prm, upd, N, xy, &w_upd), SH_OK);
        assert_int_equal(sh_flow_pyramid_update_box(upd, &g.plane[0], box), SH_OK);
        sh_flow_windows_refresh(w_upd);
        assert_int_equal(sh_flow_windows_create(&prm, whole, N, xy, &w_whole), SH_OK);
        for (int dir = 0; dir < 3; dir++) {
            if (dir == 0) { /* forward from it */
                assert_int_equal(sh_flow_track(&prm, upd, next, N, xy, guess, a, sa, ea), SH_OK);
                assert_int_equal(sh_flow_track(&prm, whole, next, N, xy, guess, c, sc, ec), SH_OK);
            } else if (dir == 1) { /* backward into it */
                assert_int_equal(sh_flow_track(&prm, next, upd, N, guess, xy, a, sa, ea), SH_OK);
                assert_int_equal(sh_flow_track(&prm, next, whole, N, guess, xy, c, sc, ec), SH_OK);
            } else { /* from the refreshed windows */
                assert_int_equal(sh_flow_track_windows(&prm, w_upd, next, N, NULL, guess, a, sa, ea), SH_OK);
                assert_int_equal(sh_flow_track_windows(&prm, w_whole, next, N, NULL, guess, c, sc, ec), SH_OK);
            }
            int ok = 0;
            for (int i = 0; i < N; i++) {
                assert_int_equal(sa[i], sc[i]);
                assert_true(same_bits(a[2 * i], c[2 * i]) && same_bits(a[2 * i + 1], c[2 * i + 1]));
                assert_true(same_bits(ea[i], ec[i]));
                ok += sa[i] == SH_FLOW_OK;
            }
            assert_true(ok >= N / 2);
        }
        sh_flow_windows_destroy(w_upd);
        sh_flow_windows_destroy(w_whole);
        /* a pyramid built for a small box holds nothing beyond it to keep */
        const float small[4] = {150, 110, 160, 120}, past[4] = {150, 110, 260, 120};
        assert_int_equal(sh_flow_pyramid_build_box(upd, &g.plane[0], 1, small), SH_OK);
        assert_int_equal(sh_flow_pyramid_update_box(upd, &g.plane[0], small), SH_OK);
        assert_int_equal(sh_flow_pyramid_update_box(upd, &g.plane[0], past), SH_EINVAL);
        sh_flow_pyramid_destroy(upd);
        sh_flow_pyramid_destroy(whole);
        sh_flow_pyramid_destroy(next);
    }
    sh_image_destroy(&f0);
    sh_image_destroy(&f1);
    sh_image_destroy(&g);
}

/* The previous frame's windows sampled once (sh_flow_windows_create) give every point the result
 * sh_flow_track gives from the pyramid, bit for bit: all points, a subset in another order,
 * points near and past the edges, a flat one and a NaN; and what must be refused. */
static void test_windows_same_as_track(void **state)
{
    (void)state;
    enum { FW = 200, FH = 150, N = 12 };
    sh_image f0, f1;
    assert_int_equal(sh_image_create(&f0, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, FW, FH), SH_OK);
    render_shifted(&f0, 0, 0);
    render_shifted(&f1, 1.7, -2.2);
    for (int y = 0; y < 30; y++) memset(f0.plane[0].data + (size_t)y * f0.plane[0].stride, 120, 40); /* flat */
    pair p;
    pair_make(&p, &f0, &f1, 2);
    const float xy[2 * N] = {100.3f, 75.6f, 10, 10,   3.5f, 140, 196.2f, 2.1f, -5, 80,  50, 160,
                             60.25f, 40.5f, 150, 100, 120, 30, 180, 130,    NAN, 20, 90, 90.9f};
    float guess[2 * N], a[2 * N], b[2 * N], ea[N], eb[N];
    uint8_t sa[N], sb[N];
    for (int i = 0; i < 2 * N; i++) guess[i] = xy[i] + (i % 2 ? -2.0f : 1.5f);
    sh_flow_windows *w = NULL;
    assert_int_equal(sh_flow_windows_create(&p.prm, p.a, N, xy, &w), SH_OK);
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, N, xy, guess, a, sa, ea), SH_OK);
    assert_int_equal(sh_flow_track_windows(&p.prm, w, p.b, N, NULL, guess, b, sb, eb), SH_OK);
    int ok = 0;
    for (int i = 0; i < N; i++) {
        assert_int_equal(sa[i], sb[i]);
        assert_true(same_bits(a[2 * i], b[2 * i]) && same_bits(a[2 * i + 1], b[2 * i + 1]) && same_bits(ea[i], eb[i]));
        ok += sa[i] == SH_FLOW_OK;
    }
    assert_true(ok >= 6 && ok < N);
    /* a subset, backwards, without a guess and without err */
    int idx[5] = {11, 7, 6, 2, 0};
    float sub_xy[2 * 5], c[2 * 5];
    uint8_t sc[5];
    for (int j = 0; j < 5; j++) sub_xy[2 * j] = xy[2 * idx[j]], sub_xy[2 * j + 1] = xy[2 * idx[j] + 1];
    assert_int_equal(sh_flow_track(&p.prm, p.a, p.b, 5, sub_xy, NULL, a, sa, NULL), SH_OK);
    assert_int_equal(sh_flow_track_windows(&p.prm, w, p.b, 5, idx, NULL, c, sc, NULL), SH_OK);
    for (int j = 0; j < 5; j++) {
        assert_int_equal(sa[j], sc[j]);
        assert_true(same_bits(a[2 * j], c[2 * j]) && same_bits(a[2 * j + 1], c[2 * j + 1]));
    }
    /* refusals: another point count, an index out of range, other levels, a pyramid without gradients */
    assert_int_equal(sh_flow_track_windows(&p.prm, w, p.b, N + 1, NULL, NULL, b, sb, NULL), SH_EINVAL);
    idx[2] = N;
    assert_int_equal(sh_flow_track_windows(&p.prm, w, p.b, 5, idx, NULL, c, sc, NULL), SH_EINVAL);
    sh_flow_params other = p.prm;
    other.levels = 1;
    assert_int_equal(sh_flow_track_windows(&other, w, p.b, N, NULL, NULL, b, sb, NULL), SH_EINVAL);
    sh_flow_windows *w2 = NULL;
    assert_int_equal(sh_flow_windows_create(&p.prm, p.b, N, xy, &w2), SH_EINVAL);
    assert_null(w2);
    sh_flow_windows_destroy(w);
    pair_free(&p);
    sh_image_destroy(&f0);
    sh_image_destroy(&f1);
}

/* A checkerboard of 16 px squares has its corners where four squares meet, at 15.5 + 16 k; the
 * strongest responses are the pixels next to them, and nothing else responds (edges have one
 * eigenvalue zero). */
/* Waves 7-18 px long (finer than half a window, as the landmarks' band-passed tissue), grey
 * levels around 128. */
static double fine_waves(double x, double y)
{
    static const double k[6][3] = {{0.61, 0.27, 0.3}, {-0.22, 0.71, 1.1}, {0.35, -0.48, 2.0},
                                   {0.83, 0.15, 0.7}, {-0.52, -0.37, 2.9}, {0.12, 0.44, 1.6}};
    double v = 128;
    for (int i = 0; i < 6; i++) v += 16 * sin(k[i][0] * x + k[i][1] * y + k[i][2]);
    return v;
}

/* The next frame is the previous one under a known affine x' = q0 + J (x - p0) (a shear and a
 * scale moving the window's edge by 0.6-0.8 px against a translation): each point's match is
 * known in closed form. A translation-only search is biased by the deformation across its
 * window; the previous window sampled through M = J^-1 (sh_flow_track_windows_warped) is the
 * next frame's about the match, and finds it within a few hundredths of a pixel. A NULL warp is
 * sh_flow_track_windows bit for bit. */
static void test_warped_window_follows_an_affine(void **state)
{
    (void)state;
    enum { FW = 240, FH = 200, N = 30 };
    const double J[4] = {1.05, 0.04, -0.035, 0.96}, p0[2] = {120, 100}, q0[2] = {121.3, 99.2};
    const double det = J[0] * J[3] - J[1] * J[2];
    const double Ji[4] = {J[3] / det, -J[1] / det, -J[2] / det, J[0] / det};
    sh_image f0, f1;
    assert_int_equal(sh_image_create(&f0, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, FW, FH), SH_OK);
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            double dx = x - q0[0], dy = y - q0[1];
            f0.plane[0].data[(size_t)y * f0.plane[0].stride + x] = (uint8_t)lrint(fine_waves(x, y));
            f1.plane[0].data[(size_t)y * f1.plane[0].stride + x] =
                (uint8_t)lrint(fine_waves(p0[0] + Ji[0] * dx + Ji[1] * dy, p0[1] + Ji[2] * dx + Ji[3] * dy));
        }
    pair p;
    pair_make(&p, &f0, &f1, 2);
    float xy[2 * N], guess[2 * N], truth[2 * N], warp[4 * N], a[2 * N], b[2 * N], c[2 * N], ea[N], eb[N], ec[N];
    uint8_t sa[N], sb[N], sc[N];
    const int n = grid(xy, FW, FH, 6, 5);
    for (int i = 0; i < n; i++) {
        double dx = xy[2 * i] - p0[0], dy = xy[2 * i + 1] - p0[1];
        truth[2 * i] = (float)(q0[0] + J[0] * dx + J[1] * dy);
        truth[2 * i + 1] = (float)(q0[1] + J[2] * dx + J[3] * dy);
        guess[2 * i] = truth[2 * i] + 0.6f, guess[2 * i + 1] = truth[2 * i + 1] - 0.4f;
        for (int k = 0; k < 4; k++) warp[4 * i + k] = (float)Ji[k];
    }
    sh_flow_windows *w = NULL;
    assert_int_equal(sh_flow_windows_create(&p.prm, p.a, n, xy, &w), SH_OK);
    assert_int_equal(sh_flow_track_windows(&p.prm, w, p.b, n, NULL, guess, a, sa, ea), SH_OK);
    assert_int_equal(sh_flow_track_windows_warped(&p.prm, w, p.b, n, NULL, guess, NULL, b, sb, eb), SH_OK);
    assert_int_equal(sh_flow_track_windows_warped(&p.prm, w, p.b, n, NULL, guess, warp, c, sc, ec), SH_OK);
    double ta[N], tc[N], worst_c = 0, err_a = 0, err_c = 0;
    for (int i = 0; i < n; i++) {
        assert_int_equal(sa[i], sb[i]);
        assert_true(same_bits(a[2 * i], b[2 * i]) && same_bits(a[2 * i + 1], b[2 * i + 1]) && same_bits(ea[i], eb[i]));
        assert_int_equal(sa[i], SH_FLOW_OK);
        assert_int_equal(sc[i], SH_FLOW_OK);
        ta[i] = hypot(a[2 * i] - truth[2 * i], a[2 * i + 1] - truth[2 * i + 1]);
        tc[i] = hypot(c[2 * i] - truth[2 * i], c[2 * i + 1] - truth[2 * i + 1]);
        worst_c = fmax(worst_c, tc[i]);
        err_a += ea[i] / n, err_c += ec[i] / n;
    }
    qsort(ta, (size_t)n, sizeof *ta, by_value);
    qsort(tc, (size_t)n, sizeof *tc, by_value);
    print_message("  translation: median %.4f px, worst %.4f px, window difference %.2f; warped: median %.4f px, "
                  "worst %.4f px, %.2f\n", ta[n / 2], ta[n - 1], err_a, tc[n / 2], worst_c, err_c);
    assert_true(tc[n / 2] <= 0.02 && worst_c <= 0.03);
    assert_true(ta[n / 2] > 5 * tc[n / 2]);
    assert_true(err_c < err_a);
    sh_flow_windows_destroy(w);
    pair_free(&p);
    sh_image_destroy(&f0);
    sh_image_destroy(&f1);
}

static void test_corners_of_a_checkerboard(void **state)
{
    (void)state;
    const int w = 160, h = 128, sq = 16;
    sh_image img, mask;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, w, h), SH_OK);
    assert_int_equal(sh_image_create(&mask, SH_PIX_GRAY8, w, h), SH_OK);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            img.plane[0].data[(size_t)y * img.plane[0].stride + x] =
                ((x / sq + y / sq) % 2) ? 215 : 40;
            mask.plane[0].data[(size_t)y * mask.plane[0].stride + x] = x >= w / 2;
        }
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    cp.max_points = 500;
    cp.min_distance = 8;
    float xy[2 * 500];
    int n;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_OK);
    const int inner = (w / sq - 1) * (h / sq - 1);
    assert_int_equal(n, inner);
    for (int i = 0; i < n; i++) {
        double cx = 15.5 + sq * floor((xy[2 * i] - 15.5) / sq + 0.5);
        double cy = 15.5 + sq * floor((xy[2 * i + 1] - 15.5) / sq + 0.5);
        assert_true(fabs(xy[2 * i] - cx) <= 1.0 && fabs(xy[2 * i + 1] - cy) <= 1.0);
    }
    /* the mask: only the right half */
    assert_int_equal(sh_flow_corners(&img.plane[0], &mask.plane[0], &cp, xy, &n), SH_OK);
    assert_int_equal(n, (w / sq / 2) * (h / sq - 1));
    for (int i = 0; i < n; i++) assert_true(xy[2 * i] >= w / 2);
    /* the cap */
    cp.max_points = 5;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_OK);
    assert_int_equal(n, 5);
    /* a distance of two squares leaves every other corner in each direction at most */
    cp.max_points = 500;
    cp.min_distance = 2 * sq + 0.5;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_OK);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < i; j++)
            assert_true(hypot(xy[2 * i] - xy[2 * j], xy[2 * i + 1] - xy[2 * j + 1]) >= 2 * sq + 0.5);
    assert_true(n >= (w / sq - 1) / 2 * ((h / sq - 1) / 2));
    sh_image_destroy(&img);
    sh_image_destroy(&mask);
}

/* balance_cell ranks each corner by its response over its cell's strongest: on a checkerboard
 * whose left half has a tenth of the right's contrast (a hundredth of the response), strongest
 * first takes only the right half's corners while there are enough; ranked within 16 px cells,
 * which hold one corner each, every corner scores 1, as on a board of even contrast ranked so,
 * and the choice is that board's to the order (by position, as ties are); a floor of 1 (every
 * cell's strongest taken as the frame's) is strongest first again. */
static void test_corners_balanced(void **state)
{
    (void)state;
    const int w = 160, h = 128, sq = 16;
    sh_image even, weak, mask;
    assert_int_equal(sh_image_create(&even, SH_PIX_GRAY8, w, h), SH_OK);
    assert_int_equal(sh_image_create(&weak, SH_PIX_GRAY8, w, h), SH_OK);
    assert_int_equal(sh_image_create(&mask, SH_PIX_GRAY8, w, h), SH_OK);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int dark = (x / sq + y / sq) % 2;
            even.plane[0].data[(size_t)y * even.plane[0].stride + x] = dark ? 215 : 40;
            weak.plane[0].data[(size_t)y * weak.plane[0].stride + x] = x < w / 2 ? (dark ? 136 : 119) : (dark ? 215 : 40);
            /* off the column of corners between the halves, whose squares differ in contrast */
            mask.plane[0].data[(size_t)y * mask.plane[0].stride + x] = abs(x - w / 2) > sq / 2;
        }
    enum { CAP = 28 };
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    cp.quality = 0.005;
    cp.min_distance = 8;
    float a[2 * CAP], b[2 * CAP], c[2 * CAP];
    int na, nb, nc;
    cp.max_points = 500;
    float all[2 * 500];
    const sh_plane *m = &mask.plane[0];
    assert_int_equal(sh_flow_corners(&even.plane[0], m, &cp, all, &na), SH_OK);
    assert_int_equal(na, (w / sq - 2) * (h / sq - 1)); /* the inner corners alone, less the middle's */
    cp.max_points = CAP;
    assert_int_equal(sh_flow_corners(&weak.plane[0], m, &cp, a, &na), SH_OK);
    assert_int_equal(na, CAP);
    for (int i = 0; i < na; i++) assert_true(a[2 * i] > w / 2); /* 4 x 7 corners right of the middle */
    cp.balance_cell = sq;
    assert_int_equal(sh_flow_corners(&even.plane[0], m, &cp, c, &nc), SH_OK);
    assert_int_equal(sh_flow_corners(&weak.plane[0], m, &cp, b, &nb), SH_OK);
    assert_int_equal(nb, nc);
    assert_memory_equal(b, c, sizeof(float) * 2 * (size_t)nc);
    int left = 0;
    for (int i = 0; i < nb; i++) left += b[2 * i] < w / 2;
    assert_true(left > 0);
    cp.balance_floor = 1;
    assert_int_equal(sh_flow_corners(&weak.plane[0], m, &cp, b, &nb), SH_OK);
    assert_int_equal(nb, na);
    assert_memory_equal(b, a, sizeof(float) * 2 * (size_t)na);
    sh_image_destroy(&even);
    sh_image_destroy(&weak);
    sh_image_destroy(&mask);
}

/* The landmarks look for corners in the box of their mask grown by 2 + block / 2 px alone
 * (src/landmarks, mask_box): on a textured frame with a disc-shaped mask, the corners of that box
 * (a view with the frame's stride), moved by its origin, are those of the whole frame, in the
 * same order; with blocks of 3 and 5. */
static void test_corners_in_the_masks_box(void **state)
{
    (void)state;
    const int w = 320, h = 240;
    sh_image img, mask;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, w, h), SH_OK);
    assert_int_equal(sh_image_create(&mask, SH_PIX_GRAY8, w, h), SH_OK);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double v = synth_texture(x, y, 0);
            img.plane[0].data[(size_t)y * img.plane[0].stride + x] = (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v);
            mask.plane[0].data[(size_t)y * mask.plane[0].stride + x] = hypot(x - 170.0, y - 110.0) < 70;
        }
    for (int block = 3; block <= 5; block += 2) {
        sh_flow_corner_params cp;
        sh_flow_corner_params_default(&cp);
        cp.max_points = 300;
        cp.min_distance = 6;
        cp.block = block;
        float whole[600], part[600];
        int n, m;
        assert_int_equal(sh_flow_corners(&img.plane[0], &mask.plane[0], &cp, whole, &n), SH_OK);
        const int g = 2 + block / 2, x0 = 101 - g, y0 = 41 - g, x1 = 240 + g, y1 = 180 + g;
        const sh_plane ip = {img.plane[0].data + (size_t)y0 * img.plane[0].stride + x0, x1 - x0, y1 - y0,
                             img.plane[0].stride};
        const sh_plane mp = {mask.plane[0].data + (size_t)y0 * mask.plane[0].stride + x0, x1 - x0, y1 - y0,
                             mask.plane[0].stride};
        assert_int_equal(sh_flow_corners(&ip, &mp, &cp, part, &m), SH_OK);
        assert_true(n > 50);
        assert_int_equal(m, n);
        for (int i = 0; i < n; i++) {
            assert_float_equal(part[2 * i] + x0, whole[2 * i], 0);
            assert_float_equal(part[2 * i + 1] + y0, whole[2 * i + 1], 0);
        }
    }
    sh_image_destroy(&img);
    sh_image_destroy(&mask);
}

/* sh_flow_window_difference against closed forms: a frame and the same texture moved by a whole
 * number of pixels differ by nothing where the windows follow the move (the same samples, the
 * same weights), a frame and itself plus 10 grey levels by exactly 10, and windows that cannot
 * be read, or a side that is not odd, give NaN. */
static void test_window_difference(void **state)
{
    (void)state;
    enum { FW = 160, FH = 120 };
    sh_image fa, fb, fc;
    assert_int_equal(sh_image_create(&fa, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&fb, SH_PIX_GRAY8, FW, FH), SH_OK);
    assert_int_equal(sh_image_create(&fc, SH_PIX_GRAY8, FW, FH), SH_OK);
    sh_image *moved[2] = {&fa, &fb};
    for (int k = 0; k < 2; k++) {
        render_shifted(moved[k], 3 * k, -2 * k);
        for (int y = 0; y < FH; y++)
            for (int x = 0; x < FW; x++) {
                uint8_t *v = &moved[k]->plane[0].data[(size_t)y * moved[k]->plane[0].stride + x];
                *v = (uint8_t)(*v * 200 / 255); /* room for +10 */
            }
    }
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++)
            fc.plane[0].data[(size_t)y * fc.plane[0].stride + x] =
                (uint8_t)(fa.plane[0].data[(size_t)y * fa.plane[0].stride + x] + 10);
    pair ab, ac;
    pair_make(&ab, &fa, &fb, 1);
    pair_make(&ac, &fa, &fc, 1);
    const float px = 70.3f, py = 50.6f;
    assert_true(sh_flow_window_difference(ab.a, px, py, ab.b, px + 3, py - 2, 7) == 0.0f);
    assert_true(sh_flow_window_difference(ab.a, px, py, ab.b, px, py, 7) > 1.0f);
    assert_true(sh_flow_window_difference(ac.a, px, py, ac.b, px, py, 7) == 10.0f);
    assert_true(sh_flow_window_difference(ac.a, px, py, ac.b, px, py, 21) == 10.0f);
    assert_true(isnan(sh_flow_window_difference(ac.a, px, py, ac.b, px, py, 8)));
    assert_true(isnan(sh_flow_window_difference(ac.a, px, py, ac.b, 1e6f, py, 7)));
    assert_true(isnan(sh_flow_window_difference(ac.a, px, py, ac.b, NAN, py, 7)));
    assert_true(isnan(sh_flow_window_difference(NULL, px, py, ac.b, px, py, 7)));
    pair_free(&ab);
    pair_free(&ac);
    sh_image_destroy(&fa);
    sh_image_destroy(&fb);
    sh_image_destroy(&fc);
}

/* sh_flow_window_correlation against closed forms: a frame and the same texture moved by a whole
 * number of pixels correlate by 1 where the windows follow the move, a frame and itself plus 10
 * grey levels by 1 (the correlation ignores an offset), a frame and its negative by -1; a flat
 * window gives NaN, as do windows that cannot be read; and windows of independent noise (uniform,
 * 441 pixels) correlate by less than 0.2, four standard deviations (1/21) of the correlation of
 * independent samples. */
static void test_window_correlation(void **state)
{
    (void)state;
    enum { FW = 160, FH = 120 };
    sh_image f[5];
    for (int k = 0; k < 5; k++) assert_int_equal(sh_image_create(&f[k], SH_PIX_GRAY8, FW, FH), SH_OK);
    render_shifted(&f[0], 0, 0);
    render_shifted(&f[1], 3, -2);
    uint32_t seed = 99;
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            const size_t at = (size_t)y * f[0].plane[0].stride + x;
            for (int k = 0; k < 2; k++) f[k].plane[0].data[at] = (uint8_t)(f[k].plane[0].data[at] * 200 / 255);
            f[2].plane[0].data[at] = (uint8_t)(f[0].plane[0].data[at] + 10);
            f[3].plane[0].data[at] = (uint8_t)(255 - f[0].plane[0].data[at]);
            seed = seed * 1664525u + 1013904223u;
            f[4].plane[0].data[at] = (uint8_t)(x < FW / 2 ? 128 : (seed >> 16) % 256);
        }
    pair moved, offset, negative, noise;
    pair_make(&moved, &f[0], &f[1], 1);
    pair_make(&offset, &f[0], &f[2], 1);
    pair_make(&negative, &f[0], &f[3], 1);
    pair_make(&noise, &f[4], &f[0], 1);
    const float px = 70.3f, py = 50.6f;
    assert_true(fabsf(sh_flow_window_correlation(moved.a, px, py, moved.b, px + 3, py - 2, 21) - 1) < 1e-6f);
    assert_true(fabsf(sh_flow_window_correlation(offset.a, px, py, offset.b, px, py, 21) - 1) < 1e-6f);
    assert_true(fabsf(sh_flow_window_correlation(negative.a, px, py, negative.b, px, py, 21) + 1) < 1e-4f); /* 255 - v rounds apart by 1/32 */
    /* f[4]: flat on the left half, independent noise on the right */
    assert_true(isnan(sh_flow_window_correlation(noise.a, 30, 60, noise.b, px, py, 21)));
    const float r = sh_flow_window_correlation(noise.a, 120, 60, noise.b, px, py, 21);
    print_message("  noise against texture: r = %.3f\n", r);
    assert_true(fabsf(r) < 0.2f);
    assert_true(isnan(sh_flow_window_correlation(moved.a, px, py, moved.b, px, py, 8)));
    assert_true(isnan(sh_flow_window_correlation(moved.a, px, py, moved.b, 1e6f, py, 21)));
    assert_true(isnan(sh_flow_window_correlation(NULL, px, py, moved.b, px, py, 21)));
    pair_free(&moved);
    pair_free(&offset);
    pair_free(&negative);
    pair_free(&noise);
    for (int k = 0; k < 5; k++) sh_image_destroy(&f[k]);
}

static void test_refusals(void **state)
{
    (void)state;
    sh_flow_params prm;
    sh_flow_params_default(&prm);
    sh_flow_pyramid *a = NULL, *b = NULL, *c = NULL;
    prm.win = 20;
    assert_int_equal(sh_flow_pyramid_create(64, 64, &prm, &a), SH_EINVAL);
    prm.win = 21;
    prm.levels = SH_FLOW_MAX_LEVELS + 1;
    assert_int_equal(sh_flow_pyramid_create(64, 64, &prm, &a), SH_EINVAL);
    prm.levels = 3;
    prm.max_iter = 101;
    assert_int_equal(sh_flow_pyramid_create(64, 64, &prm, &a), SH_EINVAL);
    prm.max_iter = 30;
    assert_int_equal(sh_flow_pyramid_create(1, 64, &prm, &a), SH_EINVAL);
    assert_null(a);
    /* 64 px: level 1 is 32 (> 21) and built, level 2 would be 16 (<= 21) and is not */
    assert_int_equal(sh_flow_pyramid_create(64, 64, &prm, &a), SH_OK);
    assert_int_equal(sh_flow_pyramid_levels(a), 1);
    assert_int_equal(sh_flow_pyramid_create(64, 64, &prm, &b), SH_OK);
    assert_int_equal(sh_flow_pyramid_create(64, 48, &prm, &c), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 64, 48), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(a, &img.plane[0], 1), SH_EINVAL);
    assert_int_equal(sh_flow_pyramid_build(c, &img.plane[0], 1), SH_OK);
    sh_image_destroy(&img);
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 64, 64), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(a, &img.plane[0], 0), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(b, &img.plane[0], 0), SH_OK);
    float xy[2] = {30, 30}, out[2];
    uint8_t st[1];
    /* tracked from a pyramid built without its gradients */
    assert_int_equal(sh_flow_track(&prm, a, b, 1, xy, NULL, out, st, NULL), SH_EINVAL);
    assert_int_equal(sh_flow_pyramid_build(a, &img.plane[0], 1), SH_OK);
    assert_int_equal(sh_flow_track(&prm, a, c, 1, xy, NULL, out, st, NULL), SH_EINVAL);
    assert_int_equal(sh_flow_track(&prm, a, b, 1, xy, NULL, out, st, NULL), SH_OK);
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    int n;
    cp.block = 4;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_EINVAL);
    cp.block = 3;
    cp.quality = 0;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_EINVAL);
    cp.quality = 0.01;
    const struct { int cell; double floor; } bad_balance[] = {{-1, 0}, {4097, 0}, {16, -0.1}, {16, 1.5}, {16, NAN}};
    for (size_t k = 0; k < sizeof bad_balance / sizeof bad_balance[0]; k++) {
        cp.balance_cell = bad_balance[k].cell, cp.balance_floor = bad_balance[k].floor;
        assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_EINVAL);
    }
    cp.balance_cell = 0, cp.balance_floor = 0;
    sh_image small;
    assert_int_equal(sh_image_create(&small, SH_PIX_GRAY8, 32, 64), SH_OK);
    assert_int_equal(sh_flow_corners(&img.plane[0], &small.plane[0], &cp, xy, &n), SH_EINVAL);
    /* a frame without texture has no corner */
    cp.max_points = 1;
    assert_int_equal(sh_flow_corners(&img.plane[0], NULL, &cp, xy, &n), SH_OK);
    assert_int_equal(n, 0);
    sh_image_destroy(&small);
    sh_image_destroy(&img);
    sh_flow_pyramid_destroy(a);
    sh_flow_pyramid_destroy(b);
    sh_flow_pyramid_destroy(c);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_subpixel_shift),
        cmocka_unit_test(test_large_shift_needs_levels_or_guess),
        cmocka_unit_test(test_deformation_against_truth),
        cmocka_unit_test(test_flat_outside_and_bad_points),
        cmocka_unit_test(test_box_build_same_as_whole),
        cmocka_unit_test(test_update_box_same_as_whole),
        cmocka_unit_test(test_windows_same_as_track),
        cmocka_unit_test(test_warped_window_follows_an_affine),
        cmocka_unit_test(test_corners_of_a_checkerboard),
        cmocka_unit_test(test_corners_balanced),
        cmocka_unit_test(test_corners_in_the_masks_box),
        cmocka_unit_test(test_window_difference),
        cmocka_unit_test(test_window_correlation),
        cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
