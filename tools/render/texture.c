/* Procedural textures. The tissue must look like tissue to an intensity metric: structure at
 * every scale (so that misregistration shows), vessels with fat along them, no repetition. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>

#include "render.h"

void rd_texture_free(rd_texture *t)
{
    free(t->rgb);
    t->rgb = NULL;
}

static uint32_t hash3(uint32_t x, uint32_t y, uint32_t s)
{
    uint32_t h = x * 0x8da6b343u ^ y * 0xd8163841u ^ s * 0xcb1ab31fu;
    h ^= h >> 15;
    h *= 0x2c1b3c6du;
    h ^= h >> 12;
    h *= 0x297a2d39u;
    h ^= h >> 15;
    return h;
}

/* Value noise in [0, 1] with a smooth (C1) interpolant; x, y >= 0. */
static float vnoise(float x, float y, uint32_t seed)
{
    int xi = (int)x, yi = (int)y;
    float fx = x - xi, fy = y - yi;
    fx = fx * fx * (3 - 2 * fx);
    fy = fy * fy * (3 - 2 * fy);
    float a = hash3((uint32_t)xi, (uint32_t)yi, seed) * (1.0f / 4294967296.0f);
    float b = hash3((uint32_t)xi + 1, (uint32_t)yi, seed) * (1.0f / 4294967296.0f);
    float c = hash3((uint32_t)xi, (uint32_t)yi + 1, seed) * (1.0f / 4294967296.0f);
    float d = hash3((uint32_t)xi + 1, (uint32_t)yi + 1, seed) * (1.0f / 4294967296.0f);
    return (a + (b - a) * fx) + ((c + (d - c) * fx) - (a + (b - a) * fx)) * fy;
}

static float fbm(float x, float y, int octaves, uint32_t seed)
{
    float s = 0, amp = 0.5f, norm = 0;
    for (int o = 0; o < octaves; o++) {
        s += amp * vnoise(x, y, seed + 131u * (uint32_t)o);
        norm += amp;
        x *= 2.03f;
        y *= 2.03f;
        amp *= 0.5f;
    }
    return s / norm;
}

static uint64_t rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double rng_uniform(uint64_t *s, double lo, double hi)
{
    return lo + (hi - lo) * (double)(rng_next(s) >> 11) * (1.0 / 9007199254740992.0);
}

/* Stamps a vessel segment into the distance field (texels): vd = min distance / width. */
static void stamp(float *vd, int w, int h, double ax, double ay, double bx, double by, double width,
                  double reach)
{
    int x0 = (int)floor(fmin(ax, bx) - reach), x1 = (int)ceil(fmax(ax, bx) + reach);
    int y0 = (int)floor(fmin(ay, by) - reach), y1 = (int)ceil(fmax(ay, by) + reach);
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x1 > w - 1) x1 = w - 1;
    if (y1 > h - 1) y1 = h - 1;
    double dx = bx - ax, dy = by - ay, l2 = dx * dx + dy * dy;
    for (int y = y0; y <= y1; y++)
        for (int x = x0; x <= x1; x++) {
            double px = x + 0.5 - ax, py = y + 0.5 - ay;
            double s = l2 > 0 ? (px * dx + py * dy) / l2 : 0;
            s = s < 0 ? 0 : (s > 1 ? 1 : s);
            double ex = px - s * dx, ey = py - s * dy;
            float d = (float)(sqrt(ex * ex + ey * ey) / width);
            if (d < vd[(size_t)y * w + x]) vd[(size_t)y * w + x] = d;
        }
}

/* A vessel: a meandering path that thins as it goes and sheds branches. */
static void vessel(float *vd, int w, int h, uint64_t *rng, double x, double y, double dir,
                   double width, double length, int depth)
{
    double step = 6.0 * width;
    while (length > 0 && width > 1.2) {
        double nd = dir + rng_uniform(rng, -0.25, 0.25);
        double nx = x + step * cos(nd), ny = y + step * sin(nd);
        stamp(vd, w, h, x, y, nx, ny, width, width * 7.0);
        if (depth < 2 && rng_uniform(rng, 0, 1) < 0.09)
            vessel(vd, w, h, rng, nx, ny, nd + (rng_uniform(rng, 0, 1) < 0.5 ? -1 : 1) * rng_uniform(rng, 0.5, 1.1),
                   width * 0.6, length * 0.45, depth + 1);
        x = nx;
        y = ny;
        dir = nd;
        width *= 0.985;
        length -= step;
    }
}

static float smooth(float e0, float e1, float x)
{
    float t = (x - e0) / (e1 - e0);
    t = t < 0 ? 0 : (t > 1 ? 1 : t);
    return t * t * (3 - 2 * t);
}

/* One texel of the tissue at (u, v) mm from the patch corner, d texels from the nearest vessel:
 * its colour before the rim's fade, and that fade. */
static void tissue_texel(const phantom_model *m, float d, float u, float v, uint32_t seed, float c[3], float *rim_out)
{
    float low = fbm(u / 14.0f + 3, v / 14.0f + 3, 3, seed);
    float mid = fbm(u / 2.5f + 7, v / 2.5f + 7, 3, seed + 1000);
    float fine = vnoise(u * 2.2f + 11, v * 2.2f + 11, seed + 2000);
    /* fibre direction: streaks along a slowly turning angle */
    float streak = vnoise(u * 0.9f + v * 0.35f + 50, v * 3.0f - u * 1.1f + 50, seed + 3000);
    float shade = 0.72f + 0.45f * low + 0.22f * mid + 0.12f * fine + 0.08f * streak;
    float r = 150 * shade, g = 42 * shade + 10 * mid, b = 45 * shade + 6 * fine;
    /* fat hugs the vessels and lies in patches elsewhere */
    float fatness = smooth(0.68f, 0.80f, fbm(u / 9.0f + 20, v / 9.0f + 20, 4, seed + 4000) +
                                             0.30f * smooth(5.0f, 1.4f, d));
    float fr = 225 - 30 * mid, fg = 185 - 35 * mid + 10 * fine, fb = 105 - 20 * mid;
    r += (fr - r) * fatness;
    g += (fg - g) * fatness;
    b += (fb - b) * fatness;
    float vessel_a = smooth(1.15f, 0.7f, d);
    float vr = 95 + 30 * fine, vg = 22 + 10 * fine, vb = 48 + 10 * mid;
    r += (vr - r) * vessel_a;
    g += (vg - g) * vessel_a;
    b += (vb - b) * vessel_a;
    /* the rim of the patch fades into the drape's shadow */
    float edge = fminf(fminf(u, (float)m->size_u - u), fminf(v, (float)m->size_v - v));
    *rim_out = 0.55f + 0.45f * smooth(0.0f, 4.0f, edge);
    c[0] = r, c[1] = g, c[2] = b;
}

sh_status rd_texture_tissue(const phantom_model *m, int w, int h, rd_texture *out)
{
    out->width = w;
    out->height = h;
    out->rgb = malloc((size_t)w * h * 3);
    float *vd = malloc(sizeof(float) * (size_t)w * h);
    if (!out->rgb || !vd) {
        free(vd);
        rd_texture_free(out);
        return sh_error_set(SH_ENOMEM, "tissue texture %dx%d: out of memory", w, h);
    }
    for (size_t i = 0; i < (size_t)w * h; i++) vd[i] = 1e9f;
    uint64_t rng = m->seed * 0x9E3779B97F4A7C15ull + 77;
    double tpm = w / m->size_u; /* texels per mm */
    /* a main artery running diagonally (like the LAD), two lesser ones, then small branches */
    vessel(vd, w, h, &rng, w * 0.12, h * 1.02, -0.9, 1.6 * tpm, 1.6 * w, 0);
    vessel(vd, w, h, &rng, w * 0.98, h * 0.75, -2.6, 1.1 * tpm, 1.0 * w, 0);
    vessel(vd, w, h, &rng, w * 0.55, -0.02 * h, 1.7, 0.9 * tpm, 0.7 * w, 0);
    for (int k = 0; k < 6; k++) {
        /* one draw per statement: C leaves the order of function arguments open, and gcc takes
         * them right to left on x86-64, left to right on aarch64 (this is x86-64's order) */
        double dir = rng_uniform(&rng, 0, 6.283), vy = rng_uniform(&rng, 0, h);
        double vx = rng_uniform(&rng, 0, w);
        vessel(vd, w, h, &rng, vx, vy, dir, 0.45 * tpm, 0.25 * w, 1);
    }
    uint32_t seed = (uint32_t)(m->seed * 2654435761u);
    float cell = (float)(1.0 / tpm); /* mm per texel */
    /* --texture-contrast: each texel's colour about the texture's mean, scaled (a first pass
     * finds the mean); the rim's fade is applied after, as without it */
    const float contrast = m->texture_contrast > 0 ? (float)m->texture_contrast : 1;
    double mean[3] = {0, 0, 0};
    if (contrast != 1) {
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                float c[3], rim;
                tissue_texel(m, vd[(size_t)y * w + x], x * cell, y * cell, seed, c, &rim);
                for (int k = 0; k < 3; k++) mean[k] += c[k];
            }
        for (int k = 0; k < 3; k++) mean[k] /= (double)w * h;
    }
    for (int y = 0; y < h; y++) {
        uint8_t *row = out->rgb + (size_t)y * w * 3;
        for (int x = 0; x < w; x++) {
            float c[3], rim;
            tissue_texel(m, vd[(size_t)y * w + x], x * cell, y * cell, seed, c, &rim);
            if (contrast != 1)
                for (int k = 0; k < 3; k++) c[k] = fmaxf(0, (float)mean[k] + contrast * (c[k] - (float)mean[k]));
            row[3 * x] = (uint8_t)fminf(255, c[0] * rim);
            row[3 * x + 1] = (uint8_t)fminf(255, c[1] * rim);
            row[3 * x + 2] = (uint8_t)fminf(255, c[2] * rim);
        }
    }
    free(vd);
    return SH_OK;
}

sh_status rd_texture_drape(uint64_t seed, int camera, int w, int h, rd_texture *out)
{
    out->width = w;
    out->height = h;
    out->rgb = malloc((size_t)w * h * 3);
    if (!out->rgb) return sh_error_set(SH_ENOMEM, "drape %dx%d: out of memory", w, h);
    uint32_t s = (uint32_t)(seed * 40503u + 9);
    float k = 1920.0f / w; /* the weave keeps its size in the scene whatever the resolution */
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float fx = (x + 157.0f * camera) * k + 64, fy = y * k + 64;
            float weave = 0.5f + 0.25f * sinf(fx * 1.5707963f) * sinf(fy * 1.5707963f);
            float n = fbm(fx / 9.0f, fy / 9.0f, 3, s), fold = fbm(fx / 160.0f, fy / 160.0f, 2, s + 7);
            float shade = 0.35f + 0.15f * weave + 0.2f * n + 0.45f * fold;
            uint8_t *p = out->rgb + ((size_t)y * w + x) * 3;
            p[0] = (uint8_t)fminf(255, 40 * shade);
            p[1] = (uint8_t)fminf(255, 105 * shade);
            p[2] = (uint8_t)fminf(255, 115 * shade);
        }
    return SH_OK;
}

sh_status rd_texture_tag(const char *family, int id, int scale, rd_texture *out, int *total_bits,
                         int *border_bits)
{
    apriltag_family_t *f = NULL;
    void (*destroy)(apriltag_family_t *) = NULL;
    if (!strcmp(family, "tag36h11")) f = tag36h11_create(), destroy = tag36h11_destroy;
    else if (!strcmp(family, "tag25h9")) f = tag25h9_create(), destroy = tag25h9_destroy;
    else if (!strcmp(family, "tag16h5")) f = tag16h5_create(), destroy = tag16h5_destroy;
    else if (!strcmp(family, "tagStandard41h12")) f = tagStandard41h12_create(), destroy = tagStandard41h12_destroy;
    if (!f) return sh_error_set(SH_EINVAL, "tag family %s: not supported", family);
    if (id < 0 || (uint32_t)id >= f->ncodes) {
        destroy(f);
        return sh_error_set(SH_EINVAL, "%s has no id %d", family, id);
    }
    image_u8_t *im = apriltag_to_image(f, id);
    destroy(f);
    if (!im) return sh_error_set(SH_ENOMEM, "tag image: out of memory");
    int bits = phantom_sticker_bits(family, border_bits);
    int margin = (bits - im->width) / 2; /* white bits added around the family's image */
    *total_bits = bits;
    int n = bits * scale;
    out->width = out->height = n;
    out->rgb = malloc((size_t)n * n * 3);
    if (!out->rgb) {
        image_u8_destroy(im);
        return sh_error_set(SH_ENOMEM, "tag texture: out of memory");
    }
    /* printed ink: black is not 0 and paper is not 255 */
    for (int y = 0; y < n; y++)
        for (int x = 0; x < n; x++) {
            int bx = x / scale - margin, by = y / scale - margin;
            int white = bx < 0 || by < 0 || bx >= im->width || by >= im->height ||
                        im->buf[by * im->stride + bx] > 127;
            memset(out->rgb + ((size_t)y * n + x) * 3, white ? 238 : 22, 3);
        }
    image_u8_destroy(im);
    return SH_OK;
}
