#include "synth.h"

#include <math.h>

double synth_texture(double x, double y, int c)
{
    /* Incommensurate waves at wavelengths of 15-70 px plus a few blobs: detail everywhere at
     * the scale the warp must get right, and smooth enough for bilinear sampling. */
    static const double wave[3][4][3] = {
        {{0.071, 0.043, 0.3}, {-0.031, 0.089, 1.1}, {0.017, -0.023, 2.0}, {0.11, 0.05, 0.7}},
        {{0.052, -0.067, 0.9}, {0.093, 0.021, 2.3}, {-0.027, -0.041, 0.4}, {0.06, 0.12, 1.7}},
        {{-0.081, 0.034, 1.9}, {0.024, 0.077, 0.1}, {0.047, -0.058, 2.7}, {0.13, -0.02, 0.2}},
    };
    double v = 128;
    for (int k = 0; k < 4; k++) v += 28 * sin(wave[c][k][0] * x + wave[c][k][1] * y + wave[c][k][2]);
    v += 30 * sin(0.004 * x * y / 40 + c);
    return v < 0 ? 0 : (v > 255 ? 255 : v);
}

void synth_forward(const synth_motion *m, double t, double x, double y, double *fx, double *fy)
{
    double cx = m->width / 2.0, cy = m->height / 2.0, scale = m->width / 2.0;
    double u = (x - cx) / scale, v = (y - cy) / scale; /* about -1..1 */
    double a = m->amplitude, phase = 2 * M_PI * t;
    /* both rhythms vanish at t = 0, which makes frame 0 the undeformed reference */
    double s1 = sin(phase), s2 = sin(2 * phase + 0.5) - sin(0.5);
    /* affine part: translation, a little rotation and dilation */
    double dx = a * (0.6 * s1 + 0.02 * s2 * u - 0.03 * s1 * v);
    double dy = a * (-0.4 * s2 + 0.03 * s1 * u + 0.025 * s2 * v);
    /* non-affine part: a bulge and a twist with different phases */
    double bulge = exp(-((u - 0.25) * (u - 0.25) + (v + 0.1) * (v + 0.1)) / 0.18);
    double twist = exp(-((u + 0.35) * (u + 0.35) + (v - 0.15) * (v - 0.15)) / 0.12);
    dx += a * 0.5 * (s1 * bulge * (u - 0.25) * 3 - s2 * twist * (v - 0.15) * 4);
    dy += a * 0.5 * (s1 * bulge * (v + 0.1) * 3 + s2 * twist * (u + 0.35) * 4);
    dx += a * 0.15 * s2 * sin(2.1 * u + 1.3 * v);
    dy += a * 0.15 * s1 * cos(1.7 * u - 2.2 * v);
    *fx = x + dx;
    *fy = y + dy;
}

/* The reference point that lands on (x, y): fixed-point iteration q <- p - (f(q) - q), which
 * converges because the displacement's gradient is well below 1. */
static void inverse(const synth_motion *m, double t, double x, double y, double *qx, double *qy)
{
    double u = x, v = y;
    for (int k = 0; k < 60; k++) {
        double fx, fy;
        synth_forward(m, t, u, v, &fx, &fy);
        double nu = x - (fx - u), nv = y - (fy - v);
        double change = fabs(nu - u) + fabs(nv - v);
        u = nu;
        v = nv;
        if (change < 1e-9) break;
    }
    *qx = u;
    *qy = v;
}

static unsigned char clamp8(double v)
{
    v = floor(v + 0.5);
    return (unsigned char)(v < 0 ? 0 : (v > 255 ? 255 : v));
}

void synth_render(const synth_motion *m, double t, sh_image *img)
{
    for (int p = 0; p < img->num_planes; p++) {
        sh_plane *pl = &img->plane[p];
        double scale = (img->format == SH_PIX_I420 && p > 0) ? 2 : 1;
        double off = scale == 2 ? 0.5 : 0; /* 420jpeg siting */
        for (int y = 0; y < pl->height; y++) {
            for (int x = 0; x < pl->width; x++) {
                double qx, qy;
                inverse(m, t, scale * x + off, scale * y + off, &qx, &qy);
                double r = synth_texture(qx, qy, 0), g = synth_texture(qx, qy, 1),
                       b = synth_texture(qx, qy, 2);
                uint8_t *out = pl->data + (size_t)y * pl->stride;
                switch (img->format) {
                case SH_PIX_RGB24:
                    out[3 * x] = clamp8(r);
                    out[3 * x + 1] = clamp8(g);
                    out[3 * x + 2] = clamp8(b);
                    break;
                case SH_PIX_GRAY8:
                    out[x] = clamp8(r);
                    break;
                default: /* BT.601 full range */
                    if (p == 0) out[x] = clamp8(0.299 * r + 0.587 * g + 0.114 * b);
                    else if (p == 1) out[x] = clamp8(128 - 0.168736 * r - 0.331264 * g + 0.5 * b);
                    else out[x] = clamp8(128 + 0.5 * r - 0.418688 * g - 0.081312 * b);
                }
            }
        }
    }
}

void synth_markers(const synth_motion *m, int n, unsigned seed, double *ref_xy)
{
    int cols = (int)ceil(sqrt(n * (double)m->width / m->height));
    int rows = (n + cols - 1) / cols;
    double x0 = 0.12 * m->width, x1 = 0.88 * m->width, y0 = 0.12 * m->height,
           y1 = 0.88 * m->height;
    double cw = (x1 - x0) / cols, ch = (y1 - y0) / rows;
    unsigned s = seed * 2654435761u + 12345u;
    for (int i = 0; i < n; i++) {
        int c = i % cols, r = i / cols;
        s = s * 1664525u + 1013904223u;
        double jx = ((s >> 8) & 0xffff) / 65535.0 - 0.5;
        s = s * 1664525u + 1013904223u;
        double jy = ((s >> 8) & 0xffff) / 65535.0 - 0.5;
        ref_xy[2 * i] = x0 + (c + 0.5 + 0.6 * jx) * cw;
        ref_xy[2 * i + 1] = y0 + (r + 0.5 + 0.6 * jy) * ch;
    }
}
