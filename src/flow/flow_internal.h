/* The pyramid's layout, shared by its builder (pyramid.c) and the tracker (lk.c). */
#ifndef STILLHEART_FLOW_INTERNAL_H
#define STILLHEART_FLOW_INTERNAL_H

#include "stillheart/flow.h"

/* One level: its pixels, with `pad` samples of border on every side so that a window whose
 * corner lies up to one window outside the level reads memory of the level: the border mirrors
 * the level (OpenCV's BORDER_REFLECT_101). The plane also has FLOW_SLACK bytes after its last
 * row, which the 8-lane kernels may read (and ignore). The Scharr gradients a window of it needs
 * are made with the window (flow_window_gradients), zero outside the level (OpenCV's
 * BORDER_CONSTANT): a frame's windows read a third of the pixels of the part built for them, and
 * a gradient made there from pixels in the cache costs less than a whole part's written to memory
 * and read back. */
typedef struct {
    int width, height;
    int stride;         /* samples per row */
    uint8_t *img;       /* pixel (0, 0): img_base + pad * stride + pad */
    /* what the last build made (sh_flow_pyramid_build_box builds part of a level): pixels in
     * [img_box[0], img_box[2]) x [img_box[1], img_box[3]), and where gradients can be made
     * (their neighbours built, or outside the level) in grad_box, level coordinates, reaching
     * into the border where the part touches the level's edge; the tracker reads nothing outside
     * them (SH_FLOW_UNBUILT) */
    int img_box[4], grad_box[4];
} flow_level;

#define FLOW_SLACK 64


struct sh_flow_pyramid {
    int levels;  /* built above the base */
    int pad;     /* the window side */
    int has_gradients;
    flow_level level[SH_FLOW_MAX_LEVELS + 1];
    uint16_t *rows; /* the reductions' scratch: one level row of column sums */
    void *block;    /* every level's memory, one allocation */
};

/* A window's samples, rows FLOW_WROW(win) apart (the side rounded up to 8 lanes), the lanes
 * past the side zero. */
#define FLOW_WROW(win) (((win) + 7) & ~7)

/* The gradients of a window at integer corner (ix, iy) of level l: Scharr's 3x3 ([3 10 3]
 * across, [-1 0 1] along), unscaled (32 times the pixel difference per pixel) as OpenCV's tracker
 * keeps them, at the pixels [ix, ix + win] x [iy, iy + win] (the window's and their bilinear
 * neighbours) into rows of FLOW_GROW(win) in gx and gy; zero outside the level and in the rows'
 * columns past win. */
#define FLOW_GROW(win) (FLOW_WROW(win) + 8)
void flow_window_gradients(const flow_level *l, int ix, int iy, int win, int16_t *gx, int16_t *gy);
/* The previous frame's window at integer corner (ix, iy) of level l with bilinear weights w
 * (14 bits, summing to 2^14): its pixels in 1/32 grey levels (I), its gradients (gx, gy), and
 * the sums of gx^2, gx*gy, gy^2 (a). The lanes past the side are set to zero. */
void flow_window_prev(const flow_level *l, int ix, int iy, const int w[4], int win, int16_t *I,
                      int16_t *gx, int16_t *gy, int64_t a[3]);
/* The next frame's window at (ix, iy) with weights w against the previous one: the sums of
 * d * gx and d * gy, d being the difference in 1/32 grey levels (b). */
void flow_window_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win,
                          const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2]);
/* The sum of |d| over the window: OpenCV's error measure, once per point and search. */
int64_t flow_window_abs_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I);
/* The previous frame's window sampled through a 2x2 matrix (sh_flow_track_windows_warped):
 * (win + 2)^2 bilinear samples of level l at 16.16 fixed-point positions start + x col + y row
 * (offset by pad: every one >= 0; each sample's weights its fractions rounded to 1/128 px), in
 * 1/32 grey levels; the inner win x win of them into I, their own Scharr gradients (descaled to
 * the pyramid's units) into gx, gy, and the sums of gx^2, gx*gy, gy^2 into a, as
 * flow_window_prev. The caller has checked that every sample and its bilinear neighbour lie in
 * the level's built pixels. */
void flow_window_prev_warped(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                             const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy, int64_t a[3]);
/* The C definitions each computes bit for bit (the SIMD ones are what the two above run on
 * x86-64 and AArch64; test_flow_simd compares them). */
void flow_window_prev_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                               int16_t *I, int16_t *gx, int16_t *gy, int64_t a[3]);
void flow_window_mismatch_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                                   const int16_t *I, const int16_t *gx, const int16_t *gy,
                                   int64_t b[2]);
int64_t flow_window_abs_mismatch_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                                          const int16_t *I);
void flow_window_prev_warped_portable(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                                      const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy,
                                      int64_t a[3]);

#if defined(__x86_64__) && defined(__SSE2__) && defined(__GNUC__)
#define FLOW_X86 1
/* The comparisons' x86-64 loops, each the same integers as the portable one: SSE2 (8 lanes, every
 * x86-64), and AVX-512 (a window row of up to 32 lanes a step), which flow_window_mismatch and
 * flow_window_abs_mismatch run instead where flow_window_avx512() says this CPU has AVX-512 F
 * and BW. */
void flow_window_mismatch_sse2(const flow_level *l, int ix, int iy, const int w[4], int win,
                               const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2]);
void flow_window_mismatch_avx512(const flow_level *l, int ix, int iy, const int w[4], int win,
                                 const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2]);
int flow_window_avx512(void);
int64_t flow_window_abs_mismatch_sse2(const flow_level *l, int ix, int iy, const int w[4], int win,
                                      const int16_t *I);
int64_t flow_window_abs_mismatch_avx512(const flow_level *l, int ix, int iy, const int w[4], int win,
                                        const int16_t *I);
/* flow_window_prev_warped on 16 lanes (gathers), where flow_window_avx512() */
void flow_window_prev_warped_avx512(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                                    const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy,
                                    int64_t a[3]);
#endif

/* The index a mirror border (x -> -x, n-1+k -> n-1-k) gives to x, for any x and n >= 1. */
static inline int flow_reflect101(int x, int n)
{
    if (n == 1) return 0;
    while (x < 0 || x >= n) {
        if (x < 0) x = -x;
        if (x >= n) x = 2 * (n - 1) - x;
    }
    return x;
}

#endif
