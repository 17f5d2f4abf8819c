/* A synthetic sequence with a known answer, for tests and benchmarks: a smooth procedural
 * texture, moved by a known smooth, non-uniform deformation f_t (reference -> current), and
 * rendered exactly (each pixel inverts f_t and evaluates the texture analytically). */
#ifndef STILLHEART_TEST_SYNTH_H
#define STILLHEART_TEST_SYNTH_H

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    int width, height;
    double amplitude; /* scale of the motion in pixels (non-affine part about half of it) */
} synth_motion;

/* Texture in 0..255 for channel c (0..2) at real position (x, y) of the reference frame. */
double synth_texture(double x, double y, int c);

/* f_t: where the reference point (x, y) is at time t (t = 0 is the identity). */
void synth_forward(const synth_motion *m, double t, double x, double y, double *fx, double *fy);

/* Renders frame t into img (GRAY8, RGB24, I420 or YUV444; YUV full range BT.601). */
void synth_render(const synth_motion *m, double t, sh_image *img);

/* n markers spread over the middle of the frame (a jittered grid, deterministic for seed). */
void synth_markers(const synth_motion *m, int n, unsigned seed, double *ref_xy);

#ifdef __cplusplus
}
#endif
#endif
