/* The camera sensor: exposure gain, BT.601 limited-range RGB -> I420, and noise whose variance
 * grows with the signal (read noise plus shot noise), drawn from a counter-based stream keyed by
 * (seed, camera, frame) so that the bytes do not depend on the order frames are made in. */
#include <math.h>
#include <string.h>

#include "render.h"

/* Normal deviates at the 256 quantiles (i + 0.5)/256, in 1/64 DN: one byte of a random word
 * picks one, so a 64-bit draw makes eight samples. The tails stop at 2.9 sigma, which a sensor
 * model does not miss. */
static int16_t gauss_q6[256];
static int gauss_ready;

static uint64_t mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* Inverse normal CDF by bisection on erfc: runs 256 times at start. */
static double inv_normal(double p)
{
    double lo = -10, hi = 10;
    for (int i = 0; i < 200; i++) {
        double mid = 0.5 * (lo + hi);
        if (0.5 * erfc(-mid / sqrt(2.0)) < p) lo = mid;
        else hi = mid;
    }
    return 0.5 * (lo + hi);
}

static void gauss_init(void)
{
    for (int i = 0; i < 256; i++) gauss_q6[i] = (int16_t)lrint(64.0 * inv_normal((i + 0.5) / 256.0));
    gauss_ready = 1;
}

void rd_sensor_init(void)
{
    if (!gauss_ready) gauss_init();
}

static inline uint8_t clamp_u8(int v)
{
    return (uint8_t)(v < 0 ? 0 : (v > 255 ? 255 : v));
}

/* Fixed-point noise: deviates in 1/64 DN steps times sigma in 1/64 DN, so a sample costs a
 * table lookup, a multiply and a shift. */

static void noise_plane(uint8_t *p, size_t n, const int *sig_q6, int fixed_sig_q6, uint64_t *state)
{
    size_t i = 0;
    while (i < n) {
        uint64_t bits = mix(*state += 0x9E3779B97F4A7C15ull);
        for (int k = 0; k < 8 && i < n; k++, i++, bits >>= 8) {
            int sg = fixed_sig_q6 >= 0 ? fixed_sig_q6 : sig_q6[p[i]];
            int d = gauss_q6[bits & 0xff] * sg; /* DN * 4096 */
            p[i] = clamp_u8(p[i] + ((d + 2048) >> 12));
        }
    }
}

/* The lens: a [1 2 1]/4 blur each way on luma, about the point spread of a good lens at
 * 1-2 px. Without it llvmpipe's texture edges are nearly aliased and edge positions read from
 * the image (what a tag detector does) scatter more. Borders repeat their pixel. */
static void blur121(uint8_t *img, uint8_t *tmp, int w, int h)
{
    for (int y = 0; y < h; y++) {
        const uint8_t *s = img + (size_t)y * w;
        uint8_t *o = tmp + (size_t)y * w;
        o[0] = (uint8_t)((3 * s[0] + s[1] + 2) >> 2);
        for (int x = 1; x < w - 1; x++) o[x] = (uint8_t)((s[x - 1] + 2 * s[x] + s[x + 1] + 2) >> 2);
        o[w - 1] = (uint8_t)((s[w - 2] + 3 * s[w - 1] + 2) >> 2);
    }
    for (int y = 0; y < h; y++) {
        const uint8_t *a = tmp + (size_t)(y > 0 ? y - 1 : 0) * w, *b = tmp + (size_t)y * w;
        const uint8_t *c = tmp + (size_t)(y < h - 1 ? y + 1 : h - 1) * w;
        uint8_t *o = img + (size_t)y * w;
        for (int x = 0; x < w; x++) o[x] = (uint8_t)((a[x] + 2 * b[x] + c[x] + 2) >> 2);
    }
}

void rd_sensor_to_i420(const rd_sensor *sn, int camera, int frame, const uint8_t *rgba, int w, int h,
                       uint8_t *i420, uint8_t *scratch)
{
    uint8_t gain[256];
    int ysig[256];
    for (int v = 0; v < 256; v++) {
        double g = v * sn->gain;
        gain[v] = (uint8_t)(g >= 255 ? 255 : g + 0.5);
        /* shot noise ~ 0.05 DN^2 per DN of signal above black */
        double var = sn->read_noise * sn->read_noise + (sn->read_noise > 0 ? 0.05 * (v > 16 ? v - 16 : 0) : 0);
        ysig[v] = (int)(64.0 * sqrt(var) + 0.5);
    }
    int cw = w / 2;
    uint8_t *Y = i420, *U = i420 + (size_t)w * h, *V = U + (size_t)cw * (h / 2);
    const uint8_t *bg = sn->background[camera];
    for (int y = 0; y < h; y += 2) {
        const uint8_t *rows[2] = {rgba + (size_t)y * w * 4, rgba + (size_t)(y + 1) * w * 4};
        const uint8_t *brow[2] = {bg + (size_t)y * w * 3, bg + (size_t)(y + 1) * w * 3};
        uint8_t *yrow[2] = {Y + (size_t)y * w, Y + (size_t)(y + 1) * w};
        uint8_t *urow = U + (size_t)(y / 2) * cw, *vrow = V + (size_t)(y / 2) * cw;
        for (int x = 0; x < w; x += 2) {
            int sr = 0, sg = 0, sb = 0;
            for (int r = 0; r < 2; r++)
                for (int k = 0; k < 2; k++) {
                    const uint8_t *q = rows[r] + 4 * (x + k);
                    if (!q[3]) q = brow[r] + 3 * (x + k); /* nothing drawn here: the drape */
                    int R = gain[q[0]], G = gain[q[1]], B = gain[q[2]];
                    sr += R, sg += G, sb += B;
                    yrow[r][x + k] = (uint8_t)(((66 * R + 129 * G + 25 * B + 128) >> 8) + 16);
                }
            urow[x / 2] = (uint8_t)(((-38 * sr - 74 * sg + 112 * sb + 512) >> 10) + 128);
            vrow[x / 2] = (uint8_t)(((112 * sr - 94 * sg - 18 * sb + 512) >> 10) + 128);
        }
    }
    blur121(Y, scratch, w, h);
    if (!(sn->read_noise > 0)) return;
    uint64_t state = mix(sn->seed * 0x9E3779B97F4A7C15ull ^ mix((uint64_t)camera * 1000003u + (uint64_t)frame * 7919u + 1));
    noise_plane(Y, (size_t)w * h, ysig, -1, &state);
    int csig = (int)(64.0 * 0.6 * sn->read_noise + 0.5);
    noise_plane(U, (size_t)cw * (h / 2), NULL, csig, &state);
    noise_plane(V, (size_t)cw * (h / 2), NULL, csig, &state);
}
