/* The phantom's texture against tissue (issue 19: the phantom must not be easier to track than
 * tissue): the radially averaged power spectrum of the luma over patches of the rendered frames
 * that see the tissue alone, and its slope, the statistic published for natural and surgical
 * images (amplitude ~ 1/f^alpha; docs/landmarks.md, "The phantom's texture").
 *
 * The estimator: each n x n patch has its mean taken away and a Hann window applied (a patch is
 * not periodic: without the window the jumps at its edges would add power falling as f^-2 along
 * the axes, whatever the texture), then its 2D FFT (kissfft); |X(k)|^2 is
 * summed over the integer rings round(|k|) = 1 .. n/2 cycles per patch, over all patches. alpha
 * is minus half the least-squares slope of log P against log k over a band of rings: power falls
 * as f^-2 alpha when the amplitude falls as f^-alpha. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <kiss_fftnd.h>

#include "eval.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"
#include "stillheart/y4m.h"

struct eval_spectrum {
    int n, patches;
    kiss_fftnd_cfg cfg;
    kiss_fft_cpx *in, *out;
    float *window;   /* n: the periodic Hann window, w(i) = (1 - cos(2 pi i / n)) / 2 */
    double *power;   /* n/2 + 1 rings */
    long long *count;
};

sh_status eval_spectrum_create(int n, eval_spectrum **out)
{
    *out = NULL;
    if (n < 16 || n > 4096 || (n & (n - 1)))
        return sh_error_set(SH_EINVAL, "spectrum: patch side %d, a power of two from 16 to 4096", n);
    eval_spectrum *s = calloc(1, sizeof *s);
    int dims[2] = {n, n};
    if (s) {
        s->n = n;
        s->cfg = kiss_fftnd_alloc(dims, 2, 0, NULL, NULL);
        s->in = malloc(sizeof(kiss_fft_cpx) * (size_t)n * (size_t)n);
        s->out = malloc(sizeof(kiss_fft_cpx) * (size_t)n * (size_t)n);
        s->window = malloc(sizeof(float) * (size_t)n);
        s->power = calloc((size_t)n / 2 + 1, sizeof(double));
        s->count = calloc((size_t)n / 2 + 1, sizeof(long long));
    }
    if (!s || !s->cfg || !s->in || !s->out || !s->window || !s->power || !s->count) {
        eval_spectrum_destroy(s);
        return sh_error_set(SH_ENOMEM, "spectrum: out of memory");
    }
    for (int i = 0; i < n; i++) s->window[i] = (float)(0.5 - 0.5 * cos(2 * M_PI * i / n));
    *out = s;
    return SH_OK;
}

void eval_spectrum_destroy(eval_spectrum *s)
{
    if (!s) return;
    kiss_fft_free(s->cfg);
    free(s->in), free(s->out), free(s->window), free(s->power), free(s->count);
    free(s);
}

int eval_spectrum_patches(const eval_spectrum *s) { return s->patches; }

void eval_spectrum_add(eval_spectrum *s, const float *patch, int stride)
{
    const int n = s->n;
    double mean = 0;
    for (int y = 0; y < n; y++)
        for (int x = 0; x < n; x++) mean += patch[(size_t)y * (size_t)stride + (size_t)x];
    mean /= (double)n * n;
    for (int y = 0; y < n; y++)
        for (int x = 0; x < n; x++) {
            kiss_fft_cpx *c = &s->in[(size_t)y * (size_t)n + (size_t)x];
            c->r = (float)((patch[(size_t)y * (size_t)stride + (size_t)x] - mean) * s->window[x] * s->window[y]);
            c->i = 0;
        }
    kiss_fftnd(s->cfg, s->in, s->out);
    for (int ky = 0; ky < n; ky++)
        for (int kx = 0; kx < n; kx++) {
            int fx = kx <= n / 2 ? kx : kx - n, fy = ky <= n / 2 ? ky : ky - n;
            long ring = lround(sqrt((double)fx * fx + (double)fy * fy));
            if (ring > n / 2) continue; /* the corners: only some directions reach there */
            const kiss_fft_cpx *c = &s->out[(size_t)ky * (size_t)n + (size_t)kx];
            s->power[ring] += (double)c->r * c->r + (double)c->i * c->i;
            s->count[ring]++;
        }
    s->patches++;
}

sh_status eval_spectrum_alpha(const eval_spectrum *s, int k0, int k1, double *alpha)
{
    if (k0 < 1 || k1 <= k0 || k1 > s->n / 2)
        return sh_error_set(SH_EINVAL, "spectrum: rings %d..%d, within 1..%d", k0, k1, s->n / 2);
    if (!s->patches) return sh_error_set(SH_EINVAL, "spectrum: no patch");
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int m = 0;
    for (int k = k0; k <= k1; k++, m++) {
        double x = log((double)k), y = log(s->power[k] / (double)s->count[k]);
        sx += x, sy += y, sxx += x * x, sxy += x * y;
    }
    double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
    *alpha = -slope / 2;
    return SH_OK;
}

/* ---- on a rendered phantom ---- */

/* px: between the paper rig's tags at 1080p (stickers about 120 px wide, 190 px apart) the tissue
 * alone lies in corridors 70-80 px wide, where a 64 px square fits; its band, 16 to 4 px periods,
 * holds the scales a landmark's 21 px window is made of */
#define PATCH 64
#define GRID 8        /* px between the patches tried */
#define LATTICE 4     /* px between the points a patch's content is checked at */
#define MARGIN 2      /* px around the patch checked too: the sensor's blur spreads a sticker's edge */
#define SAMPLED 8     /* frames, spread over the sequence */

/* 1 when every lattice point of the patch at (x0, y0) grown by MARGIN sees the tissue itself,
 * visible in frame t. */
static int tissue_only(const phantom_truth *truth, int camera, int t, int x0, int y0, int w, int h)
{
    for (int y = y0 - MARGIN; y <= y0 + PATCH + MARGIN; y += LATTICE)
        for (int x = x0 - MARGIN; x <= x0 + PATCH + MARGIN; x += LATTICE) {
            phantom_content c;
            if (x < 0 || y < 0 || x >= w || y >= h ||
                phantom_truth_locate_content(truth, camera, t, x, y, &c) != SH_OK || c.marker != -1 ||
                !phantom_truth_content_visible(truth, camera, t, &c))
                return 0;
        }
    return 1;
}

/* Frame t's patches: a grid every GRID px, each wholly inside the hull of the tags'
 * centres, on the tissue alone and without a highlight (a pixel at or above highlight, the
 * landmarks' level for the frames' range). */
static sh_status frame_patches(const phantom_truth *truth, int camera, int t, const sh_plane *y, int highlight,
                               float *buf, eval_spectrum *s, eval_spectrum_result *r)
{
    const int mt = phantom_truth_model(truth)->num_markers;
    double *xy = malloc(2 * (size_t)(mt > 0 ? mt : 1) * sizeof(double));
    if (!xy) return sh_error_set(SH_ENOMEM, "spectrum: out of memory");
    int nc = 0;
    for (int i = 0; i < mt; i++) {
        int vis = 0;
        if (phantom_truth_marker(truth, camera, t, i, 4, NULL, &xy[2 * nc], &xy[2 * nc + 1], NULL, &vis) == SH_OK &&
            vis)
            nc++;
    }
    sh_hull hull;
    sh_status st = sh_hull_compute(xy, nc, &hull);
    free(xy);
    if (st != SH_OK) return SH_OK; /* fewer than 3 tags seen: no hull, no patch in this frame */
    for (int y0 = 0; y0 + PATCH <= y->height; y0 += GRID)
        for (int x0 = 0; x0 + PATCH <= y->width; x0 += GRID) {
            if (!sh_hull_contains(&hull, x0, y0) || !sh_hull_contains(&hull, x0 + PATCH - 1, y0) ||
                !sh_hull_contains(&hull, x0, y0 + PATCH - 1) ||
                !sh_hull_contains(&hull, x0 + PATCH - 1, y0 + PATCH - 1))
                continue;
            if (!tissue_only(truth, camera, t, x0, y0, y->width, y->height)) {
                r->off_tissue++;
                continue;
            }
            double sum = 0, sq = 0;
            int clipped = 0;
            for (int j = 0; j < PATCH; j++) {
                const uint8_t *row = y->data + (size_t)(y0 + j) * (size_t)y->stride + (size_t)x0;
                for (int i = 0; i < PATCH; i++) {
                    clipped |= row[i] >= highlight;
                    buf[j * PATCH + i] = row[i];
                    sum += row[i], sq += (double)row[i] * row[i];
                }
            }
            if (clipped) {
                r->highlights++;
                continue;
            }
            double mean = sum / (PATCH * PATCH);
            r->contrast += sqrt(fmax(0, sq / (PATCH * PATCH) - mean * mean)) / mean;
            eval_spectrum_add(s, buf, PATCH);
        }
    return SH_OK;
}

sh_status eval_spectrum_run(const phantom_truth *truth, int camera, const char *video_path, eval_spectrum_result *r)
{
    memset(r, 0, sizeof *r);
    sh_y4m_reader *rd;
    sh_status st = sh_y4m_reader_open(video_path, &rd);
    if (st != SH_OK) return st;
    const sh_y4m_header *h = sh_y4m_reader_header(rd);
    const int highlight = sh_landmarks_highlight_level(h->format, sh_y4m_header_full_range(h));
    const phantom_model *pm = phantom_truth_model(truth);
    sh_image frame = {0}, gray = {0};
    eval_spectrum *s = NULL;
    float *buf = malloc(sizeof(float) * PATCH * PATCH);
    if (h->width != pm->width || h->height != pm->height)
        st = sh_error_set(SH_EINVAL, "the phantom's images are %dx%d, %s's %dx%d", pm->width, pm->height,
                          video_path, h->width, h->height);
    else if (!buf)
        st = sh_error_set(SH_ENOMEM, "spectrum: out of memory");
    if (st == SH_OK) st = sh_image_create(&frame, h->format, h->width, h->height);
    if (st == SH_OK) st = eval_spectrum_create(PATCH, &s);
    const int step = (pm->frames + SAMPLED - 1) / SAMPLED;
    for (int t = 0; st == SH_OK; t++) {
        if ((st = sh_y4m_reader_read(rd, &frame)) != SH_OK) break;
        if (t % step) continue;
        const sh_plane *y;
        if ((st = sh_landmarks_luma(&frame, &gray, &y)) == SH_OK) st = frame_patches(truth, camera, t, y, highlight, buf, s, r);
        r->frames++;
    }
    if (st == SH_EEOF) st = SH_OK;
    if (st == SH_OK && !(r->patches = eval_spectrum_patches(s)))
        st = sh_error_set(SH_EINVAL, "%s: no %dx%d patch of tissue alone inside the tags' hull", video_path, PATCH,
                          PATCH);
    if (st == SH_OK) {
        r->contrast /= r->patches;
        st = eval_spectrum_alpha(s, EVAL_SPECTRUM_K0, EVAL_SPECTRUM_K1, &r->alpha);
        for (int o = 0; st == SH_OK && o < EVAL_SPECTRUM_OCTAVES; o++)
            st = eval_spectrum_alpha(s, 2 << o, 4 << o, &r->octave_alpha[o]);
    }
    eval_spectrum_destroy(s);
    free(buf);
    sh_image_destroy(&gray);
    sh_image_destroy(&frame);
    sh_y4m_reader_close(rd);
    return st;
}

int eval_spectrum_main(const char *truth_dir, int camera, int json, const char *video_path)
{
    phantom_truth *truth = NULL;
    eval_spectrum_result r;
    sh_status st = phantom_truth_open(truth_dir, &truth);
    if (st == SH_OK) st = eval_spectrum_run(truth, camera, video_path, &r);
    phantom_truth_close(truth);
    if (st != SH_OK) {
        sh_log_error("--spectrum: %s", sh_error_message());
        return 1;
    }
    if (json) {
        sh_cli_json j;
        sh_cli_json_start(&j, stdout);
        sh_cli_json_object(&j, NULL);
        sh_cli_json_int(&j, "frames", r.frames);
        sh_cli_json_int(&j, "patches", r.patches);
        sh_cli_json_int(&j, "patch", PATCH);
        sh_cli_json_int(&j, "off_tissue", r.off_tissue);
        sh_cli_json_int(&j, "highlights", r.highlights);
        sh_cli_json_number(&j, "contrast", r.contrast);
        sh_cli_json_number(&j, "alpha", r.alpha);
        sh_cli_json_array(&j, "octave_alpha");
        for (int o = 0; o < EVAL_SPECTRUM_OCTAVES; o++) sh_cli_json_number(&j, NULL, r.octave_alpha[o]);
        sh_cli_json_end(&j);
        sh_cli_json_end(&j);
    } else {
        printf("%s: %d patches of %dx%d px in %d frames (left out: %lld off the tissue, %lld with a highlight)\n",
               video_path, r.patches, PATCH, PATCH, r.frames, r.off_tissue, r.highlights);
        printf("RMS contrast (std / mean of the luma, per patch): %.4f\n", r.contrast);
        printf("amplitude spectrum ~ 1/f^alpha over %d..%d cycles per patch (%d..%d px periods): alpha %.3f\n",
               EVAL_SPECTRUM_K0, EVAL_SPECTRUM_K1, PATCH / EVAL_SPECTRUM_K1, PATCH / EVAL_SPECTRUM_K0, r.alpha);
        printf("alpha per octave:");
        for (int o = 0; o < EVAL_SPECTRUM_OCTAVES; o++) printf(" %d-%d: %.3f", 2 << o, 4 << o, r.octave_alpha[o]);
        printf("\n");
    }
    return fflush(stdout) == 0 ? 0 : 1;
}
