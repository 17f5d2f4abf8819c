/* The row fill: source positions (16.16) of one output row's pixels, from the model's affine
 * map, its triangles or its grid (warp_model_row_fill). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "warp_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* Positions along a row move linearly within a cell, a triangle or an affine map. They step in
 * 16.16 fixed point (int32, which SSE2 and NEON vectorize); the step's rounding (2^-17 px)
 * accumulates, so every RESTART pixels the position starts again from an exact value
 * (drift below 64 * 2^-17 = 5e-4 px). Positions beyond the limit (outside every frame) are
 * clamped to it. */
#define RESTART 64

static void fill_linear(double start, double step, int count, int32_t *fx)
{
    const double unit = 1 << WARP_FRAC_BITS;
    const double limit = (double)WARP_COORD_LIMIT / unit;
    for (int base = 0; base < count; base += RESTART) {
        int n = count - base < RESTART ? count - base : RESTART;
        double s = start + base * step, e = s + (n - 1) * step;
        int32_t *out = fx + base;
        if (fabs(s) < limit && fabs(e) < limit) {
            int32_t v = (int32_t)lrint(s * unit), dv = (int32_t)lrint(step * unit);
            for (int k = 0; k < n; k++, v += dv) out[k] = v;
            continue;
        }
        for (int k = 0; k < n; k++) { /* a map leaving every frame: saturate pixel by pixel */
            double p = s + k * step;
            p = p > limit ? limit : (p < -limit ? -limit : p);
            out[k] = p == p ? (int32_t)lrint(p * unit) : -WARP_COORD_LIMIT;
        }
    }
}

/* Pixels x0..x1 of an affine map a (full-resolution coordinates), in plane coordinates. */
static void fill_affine(const plane_geometry *g, double Y, int x0, int x1, const double *a,
                        int32_t *fx, int32_t *fy)
{
    double X = g->scale * x0 + g->ox;
    /* d/dx of (a X - o) / s with X = s x + o is a1 */
    fill_linear((a[0] + a[1] * X + a[2] * Y - g->ox) / g->scale, a[1], x1 - x0 + 1, fx);
    fill_linear((a[3] + a[4] * X + a[5] * Y - g->oy) / g->scale, a[4], x1 - x0 + 1, fy);
}

static void triangle_row(const sh_warp_model *m, int t, double Y, double *lo, double *hi)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    const int *v = m->tri + 3 * t;
    for (int e = 0; e < 3; e++) {
        const double *p = m->ref_xy + 2 * v[e], *q = m->ref_xy + 2 * v[(e + 1) % 3];
        double ya = fmin(p[1], q[1]), yb = fmax(p[1], q[1]);
        if (Y < ya - 1e-9 || Y > yb + 1e-9) continue;
        if (yb - ya < 1e-12) {
            *lo = fmin(*lo, fmin(p[0], q[0]));
            *hi = fmax(*hi, fmax(p[0], q[0]));
            continue;
        }
        double t01 = (Y - p[1]) / (q[1] - p[1]);
        t01 = t01 < 0 ? 0 : (t01 > 1 ? 1 : t01);
        double x = p[0] + t01 * (q[0] - p[0]);
        *lo = fmin(*lo, x);
        *hi = fmax(*hi, x);
    }
}

int warp_model_row_extent(const sh_warp_model *m, const plane_geometry *g, int py, int *first,
                          int *last)
{
    return sh_hull_plane_row(&m->hull, py, g->width, g->scale, g->ox, g->oy, first, last);
}

/* The triangles' pixel intervals on a row: with spans == NULL fills them, else records them
 * as (triangle, first pixel, last pixel) and returns how many. */
static int triangle_spans(const sh_warp_model *m, const plane_geometry *g, double Y, int first,
                          int last, int32_t *fx, int32_t *fy, int32_t *spans)
{
    int count = 0;
    int b = (int)((Y - m->band_origin) / TRIANGLE_BAND);
    if (b < 0 || b >= m->bands) return 0;
    for (int k = m->band_start[b]; k < m->band_start[b + 1]; k++) {
        int t = m->band_tris[k];
        if (Y < m->tri_ybounds[2 * t] - 1e-7 || Y > m->tri_ybounds[2 * t + 1] + 1e-7) continue;
        double lo, hi;
        triangle_row(m, t, Y, &lo, &hi);
        if (!(lo <= hi)) continue;
        /* Closed intervals with a hair of slack: a pixel on a shared edge may be written twice
         * (with the same value: the map is continuous) but never left out. */
        int s = (int)ceil((lo - g->ox) / g->scale - 1e-7);
        int e = (int)floor((hi - g->ox) / g->scale + 1e-7);
        if (s < first) s = first;
        if (e > last) e = last;
        if (s > e) continue;
        if (spans) {
            spans[3 * count] = t, spans[3 * count + 1] = s, spans[3 * count + 2] = e;
            count++;
        } else {
            fill_affine(g, Y, s, e, m->tri_map + 6 * t, fx + (s - first), fy + (s - first));
        }
    }
    return count;
}

static void fill_outside(int32_t *fx, int32_t *fy, int count)
{
    for (int k = 0; k < count; k++) fx[k] = fy[k] = -WARP_COORD_LIMIT;
}

static void fill_triangles(const sh_warp_model *m, const plane_geometry *g, int py, double Y,
                           int first, int last, int32_t *fx, int32_t *fy)
{
    if (m->span_start && g->scale == 1 && g->ox == 0 && g->oy == 0 && py < m->height) {
        /* the full-resolution plane: its spans were listed at create */
        for (int k = m->span_start[py]; k < m->span_start[py + 1]; k++) {
            const int32_t *sp = m->spans + 3 * k;
            int s = sp[1] < first ? first : sp[1], e = sp[2] > last ? last : sp[2];
            if (s > e) continue;
            if (sp[0] < 0) fill_outside(fx + (s - first), fy + (s - first), e - s + 1);
            else fill_affine(g, Y, s, e, m->tri_map + 6 * sp[0], fx + (s - first), fy + (s - first));
        }
        return;
    }
    /* Pixels the triangles miss by rounding at the hull's edge stay outside every frame. */
    fill_outside(fx, fy, last - first + 1);
    triangle_spans(m, g, Y, first, last, fx, fy, NULL);
}

sh_status warp_model_list_spans(sh_warp_model *m)
{
    const plane_geometry g = {.scale = 1, .ox = 0, .oy = 0, .width = m->width, .height = m->height};
    int most = 0; /* triangles in the fullest band: a row's spans at most */
    for (int b = 0; b < m->bands; b++)
        if (m->band_start[b + 1] - m->band_start[b] > most) most = m->band_start[b + 1] - m->band_start[b];
    /* a row's spans and the gaps between them: at most 2 most + 1 */
    int32_t *row = malloc(sizeof(int32_t) * 3 * (2 * (size_t)most + 1));
    uint8_t *covered = malloc((size_t)m->width);
    m->span_start = malloc(sizeof(int) * ((size_t)m->height + 1));
    size_t used = 0, cap = 0;
    sh_status st = SH_OK;
    if (!row || !covered || !m->span_start) {
        st = sh_error_set(SH_ENOMEM, "warp: out of memory");
        goto done;
    }
    for (int py = 0; py < m->height; py++) {
        m->span_start[py] = (int)used;
        int first, last;
        if (!warp_model_row_extent(m, &g, py, &first, &last)) continue;
        int count = triangle_spans(m, &g, py, first, last, NULL, NULL, row);
        memset(covered + first, 0, (size_t)(last - first + 1));
        for (int k = 0; k < count; k++) memset(covered + row[3 * k + 1], 1, (size_t)(row[3 * k + 2] - row[3 * k + 1] + 1));
        /* runs no triangle covers (rounding at the hull's edge): outside every frame */
        for (int x = first; x <= last; x++) {
            if (covered[x]) continue;
            int e = x;
            while (e < last && !covered[e + 1]) e++;
            row[3 * count] = -1, row[3 * count + 1] = x, row[3 * count + 2] = e;
            count++;
            x = e;
        }
        if (used + (size_t)count > cap) {
            cap = 2 * (used + (size_t)count) + 64;
            int32_t *grown = realloc(m->spans, sizeof(int32_t) * 3 * cap);
            if (!grown) {
                st = sh_error_set(SH_ENOMEM, "warp: out of memory");
                goto done;
            }
            m->spans = grown;
        }
        memcpy(m->spans + 3 * used, row, sizeof(int32_t) * 3 * (size_t)count);
        used += (size_t)count;
    }
    m->span_start[m->height] = (int)used;
done:
    free(row);
    free(covered);
    if (st != SH_OK) {
        free(m->span_start);
        m->span_start = NULL;
    }
    return st;
}

/* Nodes per chunk of the aligned fill (its stack arrays). */
#define NODE_CHUNK 128

/* The row's value and per-pixel step at nodes c0..c1 (cells c0..c1 - 1 and node c1's value),
 * 16.16, x and y side by side: vs[4 k .. 4 k + 3] = value x, value y, step x, step y of node
 * c0 + k. Returns 0 when a value leaves the fixed-point range (then the careful path). */
static int node_pass(const double *row0, const double *row1, double ty, double inv_h, int c0,
                     int c1, int32_t *vs)
{
    const double unit = 1 << WARP_FRAC_BITS, limit = (double)WARP_COORD_LIMIT / unit;
#if defined(__SSE2__)
    const __m128d t = _mm_set1_pd(ty), u = _mm_set1_pd(unit), su = _mm_set1_pd(inv_h * unit);
    const __m128d lim = _mm_set1_pd(limit), sign = _mm_set1_pd(-0.0);
    const double *a = row0 + 2 * (size_t)c0, *b = row1 + 2 * (size_t)c0;
    __m128d prev = _mm_add_pd(_mm_loadu_pd(a), _mm_mul_pd(t, _mm_sub_pd(_mm_loadu_pd(b), _mm_loadu_pd(a))));
    __m128d ok = _mm_cmplt_pd(_mm_andnot_pd(sign, prev), lim); /* false for NaN too */
    for (int k = 0; k < c1 - c0; k++) {
        a += 2, b += 2;
        __m128d next = _mm_add_pd(_mm_loadu_pd(a), _mm_mul_pd(t, _mm_sub_pd(_mm_loadu_pd(b), _mm_loadu_pd(a))));
        ok = _mm_and_pd(ok, _mm_cmplt_pd(_mm_andnot_pd(sign, next), lim));
        /* cvtpd rounds to nearest as lrint; out-of-range lanes are refused by ok below */
        __m128i v = _mm_cvtpd_epi32(_mm_mul_pd(prev, u));
        __m128i s = _mm_cvtpd_epi32(_mm_mul_pd(_mm_sub_pd(next, prev), su));
        _mm_storeu_si128((__m128i *)(vs + 4 * k), _mm_unpacklo_epi64(v, s));
        prev = next;
    }
    _mm_storel_epi64((__m128i *)(vs + 4 * (c1 - c0)), _mm_cvtpd_epi32(_mm_mul_pd(prev, u)));
    return _mm_movemask_pd(ok) == 3;
#else
    double prev[2];
    for (int k = 0; k <= c1 - c0; k++) {
        for (int c = 0; c < 2; c++) {
            size_t i = 2 * (size_t)(c0 + k) + c;
            double v = row0[i] + ty * (row1[i] - row0[i]);
            if (!(fabs(v) < limit)) return 0;
            vs[4 * k + c] = (int32_t)lrint(v * unit);
            if (k) vs[4 * (k - 1) + 2 + c] = (int32_t)lrint((v - prev[c]) * (inv_h * unit));
            prev[c] = v;
        }
    }
    return 1;
#endif
}

/* count pixels from (vx, vy), stepping (sx, sy) per pixel. */
static inline void fill_steps(int32_t *ox, int32_t *oy, int count, int32_t vx, int32_t vy,
                              int32_t sx, int32_t sy)
{
    int k = 0;
#if defined(__SSE2__)
    /* (The compiler's own vectorization of this loop costs more than it saves on short cells.) */
    /* lanes v + {0, 1, 2, 3} s in wrapping SIMD adds: lanes past count may overflow harmlessly */
    const __m128i zero = _mm_setzero_si128();
    __m128i s1x = _mm_set1_epi32(sx), s1y = _mm_set1_epi32(sy);
    __m128i s2x = _mm_add_epi32(s1x, s1x), s2y = _mm_add_epi32(s1y, s1y);
    __m128i x = _mm_add_epi32(_mm_set1_epi32(vx), _mm_add_epi32(_mm_unpacklo_epi32(zero, s1x),
                                                                _mm_unpacklo_epi64(zero, s2x)));
    __m128i y = _mm_add_epi32(_mm_set1_epi32(vy), _mm_add_epi32(_mm_unpacklo_epi32(zero, s1y),
                                                                _mm_unpacklo_epi64(zero, s2y)));
    const __m128i ix = _mm_add_epi32(s2x, s2x), iy = _mm_add_epi32(s2y, s2y);
    for (; k + 4 <= count; k += 4) {
        _mm_storeu_si128((__m128i *)(ox + k), x);
        _mm_storeu_si128((__m128i *)(oy + k), y);
        x = _mm_add_epi32(x, ix);
        y = _mm_add_epi32(y, iy);
    }
#endif
    for (; k < count; k++) {
        ox[k] = vx + k * sx;
        oy[k] = vy + k * sy;
    }
}

/* Cells c_from..c_to of a row whose pixels first..last lie in cells i0..i1 (clipped to them;
 * cell i1 also takes a pixel on its far node), a chunk of nodes at a time. */
static int fill_cells(const sh_warp_model *m, const double *row0, const double *row1, double ty,
                      int c_from, int c_to, int i1, int first, int last, int32_t *fx, int32_t *fy)
{
    const int h = m->h;
    const double inv_h = 1.0 / h;
    int32_t vs[4 * (NODE_CHUNK + 1)];
    for (int c0 = c_from; c0 <= c_to; c0 += NODE_CHUNK) {
        int c1 = c0 + NODE_CHUNK - 1 < c_to ? c0 + NODE_CHUNK - 1 : c_to;
        if (!node_pass(row0, row1, ty, inv_h, c0, c1 + 1, vs)) return 0;
        for (int i = c0; i <= c1; i++) {
            const int32_t *n = vs + 4 * (i - c0);
            int cell_x = m->gx0 + i * h;
            int x0 = cell_x > first ? cell_x : first;
            int x1 = i == i1 || cell_x + h - 1 > last ? last : cell_x + h - 1;
            int skip = x0 - cell_x;
            fill_steps(fx + (x0 - first), fy + (x0 - first), x1 - x0 + 1, n[0] + skip * n[2],
                       n[1] + skip * n[3], n[2], n[3]);
        }
    }
    return 1;
}

#if defined(__SSE2__)
/* fill_steps for n a multiple of 4 with v = (vx, vy) and s = (sx, sy) in the low lanes: the four
 * lanes v + {0, 1, 2, 3} s of x and y built in registers. */
static inline void store_steps(__m128i v, __m128i s, int n, int32_t *ox, int32_t *oy)
{
    __m128i s2 = _mm_add_epi32(s, s);
    s2 = _mm_unpacklo_epi64(s2, s2);
    __m128i q = _mm_unpacklo_epi64(v, _mm_add_epi32(v, s)); /* x0 y0 x1 y1 */
    __m128i r = _mm_add_epi32(q, s2);                       /* x2 y2 x3 y3 */
    q = _mm_shuffle_epi32(q, _MM_SHUFFLE(3, 1, 2, 0));      /* x0 x1 y0 y1 */
    r = _mm_shuffle_epi32(r, _MM_SHUFFLE(3, 1, 2, 0));
    __m128i x = _mm_unpacklo_epi64(q, r), y = _mm_unpackhi_epi64(q, r);
    _mm_storeu_si128((__m128i *)ox, x);
    _mm_storeu_si128((__m128i *)oy, y);
    if (n > 4) {
        __m128i s4 = _mm_add_epi32(s2, s2);
        __m128i ix = _mm_shuffle_epi32(s4, 0x00), iy = _mm_shuffle_epi32(s4, 0x55);
        for (int k = 4; k < n; k += 4) {
            x = _mm_add_epi32(x, ix);
            y = _mm_add_epi32(y, iy);
            _mm_storeu_si128((__m128i *)(ox + k), x);
            _mm_storeu_si128((__m128i *)(oy + k), y);
        }
    }
}

/* Whole cells ia..ib of a grid whose spacing is a multiple of 4: node_pass and fill_steps fused,
 * the four lanes v + {0, 1, 2, 3} s of x and y built from the node's (x, y) pairs in registers.
 * Same values as fill_cells. */
static int fill_whole_cells(const sh_warp_model *m, const double *row0, const double *row1,
                            double ty, int ia, int ib, int32_t *ox, int32_t *oy)
{
    const int h = m->h;
    const double unit = 1 << WARP_FRAC_BITS, limit = (double)WARP_COORD_LIMIT / unit;
    const __m128d t = _mm_set1_pd(ty), u = _mm_set1_pd(unit), su = _mm_set1_pd(1.0 / h * unit);
    const __m128d lim = _mm_set1_pd(limit), sign = _mm_set1_pd(-0.0);
    const double *a = row0 + 2 * (size_t)ia, *b = row1 + 2 * (size_t)ia;
    __m128d prev = _mm_add_pd(_mm_loadu_pd(a), _mm_mul_pd(t, _mm_sub_pd(_mm_loadu_pd(b), _mm_loadu_pd(a))));
    __m128d ok = _mm_cmplt_pd(_mm_andnot_pd(sign, prev), lim);
    for (int i = ia; i <= ib; i++, ox += h, oy += h) {
        a += 2, b += 2;
        __m128d next = _mm_add_pd(_mm_loadu_pd(a), _mm_mul_pd(t, _mm_sub_pd(_mm_loadu_pd(b), _mm_loadu_pd(a))));
        ok = _mm_and_pd(ok, _mm_cmplt_pd(_mm_andnot_pd(sign, next), lim));
        store_steps(_mm_cvtpd_epi32(_mm_mul_pd(prev, u)),                      /* vx vy 0 0 */
                    _mm_cvtpd_epi32(_mm_mul_pd(_mm_sub_pd(next, prev), su)),   /* sx sy 0 0 */
                    h, ox, oy);
        prev = next;
    }
    return _mm_movemask_pd(ok) == 3;
}
#endif

/* Full-resolution planes have a pixel on every node column: a node pass converts the row's
 * values at the node columns (and the per-pixel step to the next one) to 16.16, then each cell
 * steps from its left node's exact value, so no error carries from one cell to the next. The
 * step's rounding (2^-17 px per pixel) adds at most h 2^-17 px. Returns 0 (the row's pixels
 * partly written) when a value would leave the fixed-point range, for the careful path. */
static int fill_grid_aligned(const sh_warp_model *m, const double *row0, const double *row1,
                             double ty, int first, int last, int32_t *fx, int32_t *fy)
{
    const int h = m->h;
    if (first < m->gx0) return 0;
    int i0 = (first - m->gx0) / h, i1 = (last - m->gx0) / h;
    if (i1 == m->nx - 1) i1--; /* a pixel on the last node column: the last cell's far end */
    if (i0 > i1 || i1 > m->nx - 2) return 0;
#if defined(__SSE2__)
    if (h % 4 == 0) {
        int ia = m->gx0 + i0 * h == first ? i0 : i0 + 1;
        int ib = (last + 1 - m->gx0) / h - 1; /* the last cell whose h pixels all lie in the row */
        if (ib >= i1) ib = m->gx0 + i1 * h + h - 1 == last ? i1 : i1 - 1; /* far-node pixel */
        if (ia <= ib) {
            int xa = m->gx0 + ia * h;
            return (ia == i0 || fill_cells(m, row0, row1, ty, i0, ia - 1, i1, first, last, fx, fy)) &&
                   fill_whole_cells(m, row0, row1, ty, ia, ib, fx + (xa - first), fy + (xa - first)) &&
                   (ib == i1 || fill_cells(m, row0, row1, ty, ib + 1, i1, i1, first, last, fx, fy));
        }
    }
#endif
    return fill_cells(m, row0, row1, ty, i0, i1, i1, first, last, fx, fy);
}

#if defined(__SSE2__)
/* Cells of fill_grid's loop below, x and y in the two lanes of the same operations, so the same
 * doubles and the same rounding (cvtpd2dq rounds to nearest as lrint): each cell's right node
 * value from a, b (its row0 and row1 entries; the next cell's follow), then start and step as
 * fill_linear takes them, for `cells` cells of n pixels each, the first pixel of each dx from its
 * left node. When fill_linear would take its careful path in one of them (a cell over RESTART
 * pixels, a value out of range or NaN) returns 0, pixels partly written and left[] unchanged;
 * else sets left[] to the last right node's values and returns 1. Subsampled chroma rows are
 * cells of a few pixels, where two fill_linear calls a cell cost more than their pixels. */
static int fill_cells_scaled(const double *a, const double *b, double ty, const double *off,
                             double inv_scale, double inv_h, double scale, double dx, int n,
                             int cells, double *left, int32_t *fx, int32_t *fy)
{
    const double unit = 1 << WARP_FRAC_BITS, limit = (double)WARP_COORD_LIMIT / unit;
    if (n > RESTART) return 0;
    const __m128d t = _mm_set1_pd(ty), o = _mm_loadu_pd(off), is = _mm_set1_pd(inv_scale);
    const __m128d ih = _mm_set1_pd(inv_h), d = _mm_set1_pd(dx), sc = _mm_set1_pd(scale);
    const __m128d span = _mm_set1_pd((double)(n - 1)), u = _mm_set1_pd(unit);
    const __m128d sign = _mm_set1_pd(-0.0), lim = _mm_set1_pd(limit);
    __m128d l = _mm_loadu_pd(left);
    for (int c = 0; c < cells; c++, a += 2, b += 2, fx += n, fy += n) {
        __m128d va = _mm_loadu_pd(a), vb = _mm_loadu_pd(b);
        __m128d right = _mm_mul_pd(_mm_sub_pd(_mm_add_pd(va, _mm_mul_pd(t, _mm_sub_pd(vb, va))), o), is);
        __m128d slope = _mm_mul_pd(_mm_sub_pd(right, l), ih);
        __m128d start = _mm_add_pd(l, _mm_mul_pd(slope, d));
        __m128d step = _mm_mul_pd(slope, sc);
        __m128d end = _mm_add_pd(start, _mm_mul_pd(span, step));
        __m128d ok = _mm_and_pd(_mm_cmplt_pd(_mm_andnot_pd(sign, start), lim),
                                _mm_cmplt_pd(_mm_andnot_pd(sign, end), lim)); /* NaN: false */
        if (_mm_movemask_pd(ok) != 3) return 0; /* before fill_steps' int arithmetic */
        __m128i v = _mm_cvtpd_epi32(_mm_mul_pd(start, u)), s = _mm_cvtpd_epi32(_mm_mul_pd(step, u));
        if (n % 4 == 0) {
            store_steps(v, s, n, fx, fy);
        } else {
            int32_t vv[4], ss[4];
            _mm_storeu_si128((__m128i *)vv, v);
            _mm_storeu_si128((__m128i *)ss, s);
            fill_steps(fx, fy, n, vv[0], vv[1], ss[0], ss[1]);
        }
        l = right;
    }
    _mm_storeu_pd(left, l);
    return 1;
}
#endif

/* Grid rows: the map's value on this row at each node column (in plane units) is interpolated
 * once and carried from one cell to the next; within a cell the position moves linearly. */
static void fill_grid(const sh_warp_model *m, const plane_geometry *g, double Y, int first,
                      int last, int32_t *fx, int32_t *fy)
{
    const int h = m->h;
    const double inv_h = 1.0 / h, inv_scale = 1.0 / g->scale, off[2] = {g->ox, g->oy};
    double fy_cell = (Y - m->gy0) * inv_h;
    int j = (int)floor(fy_cell);
    if (j > m->ny - 2) j = m->ny - 2;
    if (j < 0) j = 0;
    const double ty = fy_cell - j;
    const double *row0 = m->map + 2 * (size_t)j * m->nx, *row1 = row0 + 2 * m->nx;
    if (g->scale == 1 && g->ox == 0 && fill_grid_aligned(m, row0, row1, ty, first, last, fx, fy))
        return;
    int32_t *out[2] = {fx, fy};
    int x = first;
    double X = g->scale * x + g->ox;
    int i = (int)floor((X - m->gx0) * inv_h);
    if (i > m->nx - 2) i = m->nx - 2;
    if (i < 0) i = 0;
    double left[2], right[2];
    for (int c = 0; c < 2; c++)
        left[c] = (row0[2 * i + c] + ty * (row1[2 * i + c] - row0[2 * i + c]) - off[c]) * inv_scale;
#if defined(__SSE2__)
    /* 4:2:0 chroma: after the first cell every cell has h / 2 pixels, its first one at the same
     * distance from its left node (h even: the cell bounds below advance by exactly h / 2) */
    int whole = g->scale == 2 && h % 8 == 0;
#endif
    while (x <= last) {
        double Xc = m->gx0 + (double)i * h;
        int e = i == m->nx - 2 ? last : (int)ceil((Xc + h - g->ox) * inv_scale) - 1;
        if (e > last) e = last;
        if (e < x) e = x;
#if defined(__SSE2__)
        int cells = 1;
        if (whole && x > first) { /* the whole cells before the last one and the row's end */
            int k = (last - x + 1) / (h / 2);
            if (k > m->nx - 2 - i) k = m->nx - 2 - i;
            if (k > 1) cells = k, e = x + k * (h / 2) - 1;
        }
        if (fill_cells_scaled(row0 + 2 * i + 2, row1 + 2 * i + 2, ty, off, inv_scale, inv_h, g->scale,
                              X - Xc, (e - x + 1) / cells, cells, left, fx + (x - first), fy + (x - first))) {
            x = e + 1;
            X = g->scale * x + g->ox;
            i += cells;
            continue;
        }
        if (cells > 1) { /* a careful cell among them: one at a time from here */
            whole = 0;
            continue;
        }
#endif
        for (int c = 0; c < 2; c++) {
            right[c] = (row0[2 * i + 2 + c] + ty * (row1[2 * i + 2 + c] - row0[2 * i + 2 + c]) -
                        off[c]) * inv_scale;
            double slope = (right[c] - left[c]) * inv_h; /* per full-resolution pixel */
            fill_linear(left[c] + slope * (X - Xc), slope * g->scale, e - x + 1, out[c] + (x - first));
            left[c] = right[c];
        }
        x = e + 1;
        X = g->scale * x + g->ox;
        i++;
    }
}

void warp_model_row_fill(const sh_warp_model *m, const plane_geometry *g, int py, int first,
                         int last, int32_t *fx, int32_t *fy)
{
    double Y = g->scale * py + g->oy;
    switch (m->kind) {
    case MODEL_AFFINE: fill_affine(g, Y, first, last, m->affine, fx, fy); return;
    case MODEL_TRIANGLES: fill_triangles(m, g, py, Y, first, last, fx, fy); return;
    case MODEL_GRID: fill_grid(m, g, Y, first, last, fx, fy); return;
    }
}
