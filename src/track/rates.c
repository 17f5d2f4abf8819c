/* Heartbeat and respiration rates: a harmonic-sum periodogram over all markers' recent tracks,
 * refined, and least-squares series fits. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <kiss_fftr.h>

#include "track_internal.h"

typedef struct {
    const double *x;   /* samples (NaN: missing) */
    int n;
} series_t;

/* sum over series and harmonics of |sum_j x_j exp(-i 2 pi k f t_j)|^2, t_j = j * ts */
static double harmonic_sum(double *const *x, int ns, int n, double ts, double f, int K, double nyq)
{
    double total = 0;
    double w = 2 * PI * f * ts;
    double c1 = cos(w), s1 = sin(w);
    for (int s = 0; s < ns; s++) {
        double re[HMAX + 1] = {0}, im[HMAX + 1] = {0};
        double zc = 1, zs = 0; /* exp(i w j) */
        const double *v = x[s];
        for (int j = 0; j < n; j++) {
            if (!isnan(v[j])) {
                double pc = zc, ps = zs;
                for (int k = 1; k <= K; k++) {
                    re[k] += v[j] * pc;
                    im[k] -= v[j] * ps;
                    double nc = pc * zc - ps * zs;
                    ps = pc * zs + ps * zc;
                    pc = nc;
                }
            }
            double nc = zc * c1 - zs * s1;
            zs = zc * s1 + zs * c1;
            zc = nc;
            if ((j & 63) == 63) { /* renormalise the recurrence */
                double l = sqrt(zc * zc + zs * zs);
                zc /= l;
                zs /= l;
            }
        }
        for (int k = 1; k <= K; k++)
            if (k * f < nyq) total += re[k] * re[k] + im[k] * im[k];
    }
    return total;
}

sh_status trk_rates_init(sh_tracker *t)
{
    t->fft_in = malloc(sizeof(float) * RATE_FFT_MAX);
    t->fft_out = malloc(sizeof(kiss_fft_cpx) * (RATE_FFT_MAX / 2 + 1));
    t->fft_power = malloc(sizeof(double) * (RATE_FFT_MAX / 2 + 1));
    t->basis = malloc(sizeof(double) * RATE_BASIS_TABLES * SH_TRACK_HISTORY * NC);
    if (!t->fft_in || !t->fft_out || !t->fft_power || !t->basis) return SH_ENOMEM;
    for (int i = 0, size = RATE_FFT_MIN; i < RATE_FFT_SIZES; i++, size *= 2)
        if (!(t->fft_cfg[i] = kiss_fftr_alloc(size, 0, NULL, NULL))) return SH_ENOMEM;
    return SH_OK;
}

void trk_rates_free(sh_tracker *t)
{
    for (int i = 0; i < RATE_FFT_SIZES; i++) kiss_fftr_free(t->fft_cfg[i]);
    free(t->fft_in);
    free(t->fft_out);
    free(t->fft_power);
    free(t->basis);
}

/* Golden-section search for the maximum of harmonic_sum in [a, b] (a bracket two grid bins wide):
 * 16 steps shrink it to 0.001 bin (1e-5 Hz over 22 s of history), far finer than the fits use. */
static double refine(double *const *x, int ns, int n, double ts, double a, double b, int K, double nyq)
{
    const double g = 0.6180339887498949;
    double c = b - g * (b - a), d = a + g * (b - a);
    double fc = harmonic_sum(x, ns, n, ts, c, K, nyq), fd = harmonic_sum(x, ns, n, ts, d, K, nyq);
    for (int it = 0; it < 16; it++) {
        if (fc > fd) {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = harmonic_sum(x, ns, n, ts, c, K, nyq);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = harmonic_sum(x, ns, n, ts, d, K, nyq);
        }
    }
    return 0.5 * (a + b);
}

/* The rate in [lo, hi] that maximises harmonic_sum. The grid is the zero-padded FFT's bins, at
 * most a quarter of 1 / span apart (the harmonic sum at bin b is the power at bins b, 2b, ...,
 * summed over the series: all of them from one FFT per series, where evaluating each grid point
 * directly costs O(n) per point and grows as the history squared), then a golden-section search
 * on the exact sum between the best bin's neighbours. */
static double search_rate(sh_tracker *t, double *const *x, int ns, int n, double ts, double lo, double hi, int K)
{
    double nyq = 0.5 / ts;
    if (hi > nyq * 0.95) hi = nyq * 0.95;
    int size = RATE_FFT_MIN, which = 0;
    while (size < 4 * n && which < RATE_FFT_SIZES - 1) size *= 2, which++;
    int bins = size / 2 + 1;
    kiss_fft_cpx *spec = t->fft_out;
    double *power = t->fft_power;
    for (int b = 0; b < bins; b++) power[b] = 0;
    for (int s = 0; s < ns; s++) {
        for (int j = 0; j < size; j++) t->fft_in[j] = j < n && !isnan(x[s][j]) ? (float)x[s][j] : 0.0f;
        kiss_fftr(t->fft_cfg[which], t->fft_in, spec);
        for (int b = 0; b < bins; b++) power[b] += (double)spec[b].r * spec[b].r + (double)spec[b].i * spec[b].i;
    }
    double df = 1.0 / (size * ts); /* bin spacing, Hz */
    int b0 = (int)ceil(lo / df), b1 = (int)floor(hi / df);
    double best = 0.5 * (lo + hi), bestv = -1;
    for (int b = b0 > 1 ? b0 : 1; b <= b1; b++) {
        double v = 0;
        for (int k = 1; k <= K && k * b < bins && k * b * df < nyq; k++) v += power[k * b];
        if (v > bestv) {
            bestv = v;
            best = b * df;
        }
    }
    double f = refine(x, ns, n, ts, fmax(lo, best - df), fmin(hi, best + df), K, nyq);
    /* A harmonic sum peaks at a subharmonic too: at f0 / 2 it still holds f0's power as its second
     * harmonic, and leakage at f0 / 2 and 3 f0 / 2 can outweigh f0's own higher harmonics (a
     * nearly sinusoidal beat). A heartbeat's fundamental carries the most motion, so the rate is
     * the lowest multiple d f whose own power is at least a quarter (half the amplitude) of the
     * strongest multiple's. */
    if (K >= 2) {
        double p[HMAX + 1], top = 0;
        int dmax = 1;
        for (int d = 1; d <= K && d * f <= hi; d++) {
            p[d] = harmonic_sum(x, ns, n, ts, d * f, 1, nyq);
            if (p[d] > top) top = p[d];
            dmax = d;
        }
        int d = 1;
        while (d < dmax && p[d] < 0.25 * top) d++;
        if (d > 1) f = refine(x, ns, n, ts, fmax(lo, d * f - df), fmin(hi, d * f + df), K, nyq);
    }
    return f;
}

int trk_chol_solve(double *A, double *b, int m, double *inv)
{
    for (int j = 0; j < m; j++) {
        double d = A[j * m + j];
        for (int k = 0; k < j; k++) d -= A[j * m + k] * A[j * m + k];
        if (!(d > 1e-12)) return 0;
        d = sqrt(d);
        A[j * m + j] = d;
        for (int i = j + 1; i < m; i++) {
            double s = A[i * m + j];
            for (int k = 0; k < j; k++) s -= A[i * m + k] * A[j * m + k];
            A[i * m + j] = s / d;
        }
    }
    /* forward/back substitution for b and (optionally) the inverse columns */
    for (int col = -1; col < (inv ? m : 0); col++) {
        double y[NC];
        for (int i = 0; i < m; i++) {
            double s = col < 0 ? b[i] : (i == col);
            for (int k = 0; k < i; k++) s -= A[i * m + k] * y[k];
            y[i] = s / A[i * m + i];
        }
        for (int i = m - 1; i >= 0; i--) {
            double s = y[i];
            for (int k = i + 1; k < m; k++) s -= A[k * m + i] * y[k];
            y[i] = s / A[i * m + i];
        }
        if (col < 0) memcpy(b, y, sizeof(double) * m);
        else
            for (int i = 0; i < m; i++) inv[i * m + col] = y[i];
    }
    return 1;
}

/* The LS fit's basis at every sample j of the window (row j, NC apart): 1, trend, heart cos/sin
 * pairs, resp cos/sin pairs. Built once per rate combination into one of the tracker's tables and
 * shared by every series and pass of the fits (the trigonometry per sample was most of their
 * cost). Returns the table; *m the number of basis functions. */
static const double *basis_table(sh_tracker *t, int which, int n, double ts, double fh, int nh, double fr, int nr,
                                 int *m)
{
    double *tab = t->basis + (size_t)which * SH_TRACK_HISTORY * NC;
    double tmid = 0.5 * (n - 1) * ts;
    for (int j = 0; j < n; j++) {
        double tj = j * ts, *phi = tab + (size_t)j * NC;
        int c = 0;
        phi[c++] = 1;
        phi[c++] = tj - tmid;
        for (int k = 1; k <= nh; k++) {
            phi[c++] = cos(2 * PI * k * fh * tj);
            phi[c++] = sin(2 * PI * k * fh * tj);
        }
        for (int k = 1; k <= nr; k++) {
            phi[c++] = cos(2 * PI * k * fr * tj);
            phi[c++] = sin(2 * PI * k * fr * tj);
        }
    }
    *m = 2 + 2 * nh + 2 * nr;
    return tab;
}

#define FIT_PASSES 4

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

double trk_median(double *v, int n)
{
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Least squares fit of one series; coef (m), cov (m x m, unscaled (A^T A)^-1), returns the residual
 * RMS of the inliers or -1 when the fit is impossible. Robust: refitted without the samples off by
 * more than 3 robust standard deviations (1.4826 x the median absolute residual, never less than
 * floor), so the wrong detections accepted before the rates were known do not bend the model. */
static double fit_series(const double *x, int n, const double *tab, int m, double *coef, double *cov, double floor)
{
    unsigned char out[SH_TRACK_HISTORY];
    memset(out, 0, sizeof out);
    double rms = -1;
    for (int pass = 0; pass < FIT_PASSES; pass++) {
        double A[NC * NC] = {0}, b[NC] = {0};
        int cnt = 0;
        for (int j = 0; j < n; j++) {
            if (isnan(x[j]) || out[j]) continue;
            const double *phi = tab + (size_t)j * NC;
            for (int a = 0; a < m; a++) {
                b[a] += phi[a] * x[j];
                for (int c = 0; c <= a; c++) A[a * m + c] += phi[a] * phi[c];
            }
            cnt++;
        }
        if (cnt < 2 * m) return -1;
        for (int a = 0; a < m; a++)
            for (int c = 0; c < a; c++) A[c * m + a] = A[a * m + c];
        if (!trk_chol_solve(A, b, m, cov)) return -1;
        memcpy(coef, b, sizeof(double) * m);
        double ss = 0;
        for (int j = 0; j < n; j++) {
            if (isnan(x[j]) || out[j]) continue;
            const double *phi = tab + (size_t)j * NC;
            double v = 0;
            for (int a = 0; a < m; a++) v += phi[a] * coef[a];
            ss += (x[j] - v) * (x[j] - v);
        }
        rms = sqrt(ss / (cnt > m ? cnt - m : 1));
        if (pass == FIT_PASSES - 1 || floor < 0) break;
        /* the scale from the median absolute residual of every sample: a run of wrong detections
         * inflates the RMS enough to hide inside 3 of it, not the median */
        double res[SH_TRACK_HISTORY];
        int nres = 0;
        for (int j = 0; j < n; j++) {
            if (isnan(x[j])) continue;
            const double *phi = tab + (size_t)j * NC;
            double v = 0;
            for (int a = 0; a < m; a++) v += phi[a] * coef[a];
            res[nres++] = fabs(x[j] - v);
        }
        double sorted[SH_TRACK_HISTORY];
        memcpy(sorted, res, sizeof(double) * nres);
        double lim = 3 * fmax(1.4826 * trk_median(sorted, nres), floor);
        int changed = 0;
        for (int j = 0, q = 0; j < n; j++) {
            if (isnan(x[j])) continue;
            unsigned char o = res[q++] > lim;
            if (o != out[j]) changed = 1;
            out[j] = o;
        }
        if (!changed) break;
    }
    return rms;
}

/* Copies the history of (marker, axis) into a linear buffer, oldest first; returns valid count. */
static int gather(sh_tracker *t, int mi, int a, double *out, int n)
{
    const float *h = trk_hist_at(t, mi, a);
    long first = t->hist_last - n + 1;
    int valid = 0;
    for (int j = 0; j < n; j++) {
        long s = first + j;
        double v = s < 0 ? NAN : h[s % SH_TRACK_HISTORY];
        out[j] = v;
        if (!isnan(v)) valid++;
    }
    return valid;
}

/* Sets a filter's state from an LS fit (coefficients relative to the window, time of the newest
 * sample tn), with covariance s2 * T C T^T. */
static void filter_from_fit(sh_tracker *t, axis_filter *f, const double *coef, const double *cov,
                            int m, double s2, double tn, double tmid)
{
    double T[NS * NC] = {0};
    T[0 * NC + 0] = 1;
    T[0 * NC + 1] = tn - tmid;
    int c = 2;
    for (int k = 1; k <= t->nh; k++, c += 2) {
        double w = 2 * PI * k * t->fh * tn, cw = cos(w), sw = sin(w);
        int i = 2 + 2 * (k - 1);
        T[i * NC + c] = cw;
        T[i * NC + c + 1] = sw;
        T[(i + 1) * NC + c] = sw;
        T[(i + 1) * NC + c + 1] = -cw;
    }
    for (int k = 1; k <= t->nr; k++, c += 2) {
        double w = 2 * PI * k * t->fr * tn, cw = cos(w), sw = sin(w);
        int i = 2 + 2 * HMAX + 2 * (k - 1);
        T[i * NC + c] = cw;
        T[i * NC + c + 1] = sw;
        T[(i + 1) * NC + c] = sw;
        T[(i + 1) * NC + c + 1] = -cw;
    }
    memset(f, 0, sizeof *f);
    for (int i = 0; i < NS; i++) {
        double s = 0;
        for (int j = 0; j < m; j++) s += T[i * NC + j] * coef[j];
        f->x[i] = s;
    }
    double TC[NS * NC];
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < m; j++) {
            double s = 0;
            for (int k = 0; k < m; k++) s += T[i * NC + k] * cov[k * m + j];
            TC[i * NC + j] = s;
        }
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) {
            double s = 0;
            for (int k = 0; k < m; k++) s += TC[i * NC + k] * T[j * NC + k];
            f->P[i * NS + j] = s2 * s;
        }
}

/* Removes the mean and linear trend of x's valid samples in place; returns their variance. */
static double detrend(double *x, int n)
{
    double s0 = 0, s1 = 0, s2 = 0, sx = 0, stx = 0;
    for (int j = 0; j < n; j++)
        if (!isnan(x[j])) {
            s0 += 1;
            s1 += j;
            s2 += (double)j * j;
            sx += x[j];
            stx += j * x[j];
        }
    double det = s0 * s2 - s1 * s1;
    double b = det > 0 ? (s0 * stx - s1 * sx) / det : 0, a0 = (sx - b * s1) / s0;
    double v = 0;
    for (int j = 0; j < n; j++)
        if (!isnan(x[j])) {
            x[j] -= a0 + b * j;
            v += x[j] * x[j];
        }
    return v / s0;
}

/* Candidate series, detrended in t->scratch: every tracked (marker, axis) with >= 60 % valid
 * samples; the RATE_SERIES of largest variance go to top. Returns how many went there. */
static int top_series(sh_tracker *t, int n, double **top)
{
    double *ser[MAXM * 3];
    double var[MAXM * 3];
    int ns = 0;
    for (int mi = 0; mi < t->nm; mi++) {
        if (!t->m[mi].init) continue;
        for (int a = 0; a < t->dim; a++) {
            double *x = t->scratch + (size_t)ns * SH_TRACK_HISTORY;
            int valid = gather(t, mi, a, x, n);
            if (valid < 0.6 * n) continue;
            var[ns] = detrend(x, n);
            ser[ns++] = x;
        }
    }
    int ntop = 0;
    unsigned char used[MAXM * 3] = {0};
    for (; ntop < RATE_SERIES && ntop < ns; ntop++) {
        int bi = -1;
        for (int i = 0; i < ns; i++)
            if (!used[i] && (bi < 0 || var[i] > var[bi])) bi = i;
        used[bi] = 1;
        top[ntop] = ser[bi];
    }
    return ntop;
}

/* Respiration, searched on the residual of the heart fit (top is changed to it); kept only when
 * it explains a good part of the motion, well above the noise. Returns its harmonics (0: none)
 * and its rate in *fr. */
static int search_resp(sh_tracker *t, double **top, int ntop, int n, double ts, double fh, const double *trend,
                       int m_trend, double noise2, double *fr)
{
    double coef[NC], cov[NC * NC];
    int m;
    const double *heart = basis_table(t, 0, n, ts, fh, t->o.heart_harmonics, 0, 0, &m);
    for (int i = 0; i < ntop; i++) {
        double r = fit_series(top[i], n, heart, m, coef, cov, -1);
        if (r < 0) continue;
        for (int j = 0; j < n; j++) {
            if (isnan(top[i][j])) continue;
            const double *phi = heart + (size_t)j * NC;
            double v = 0;
            for (int k = 2; k < m; k++) v += phi[k] * coef[k];
            top[i][j] -= v;
        }
    }
    double lo = fmax(t->o.resp_min_hz, 1.5 / (n * ts));
    if (!(lo < t->o.resp_max_hz)) return 0;
    double f = search_rate(t, top, ntop, n, ts, lo, t->o.resp_max_hz, t->o.resp_harmonics);
    double exr = 0, totr = 0;
    int m_resp;
    const double *resp = basis_table(t, 2, n, ts, 0, 0, f, t->o.resp_harmonics, &m_resp);
    for (int i = 0; i < ntop; i++) {
        double r0 = fit_series(top[i], n, trend, m_trend, coef, cov, -1);
        double r1 = fit_series(top[i], n, resp, m_resp, coef, cov, -1);
        if (r0 < 0 || r1 < 0) continue;
        exr += r0 * r0 - r1 * r1;
        totr += r0 * r0;
    }
    if (!(totr > 0 && exr > 0.3 * totr && exr / ntop > 4 * noise2)) return 0;
    *fr = f;
    return t->o.resp_harmonics;
}

/* Is there a heartbeat at all? The heart harmonics must carry motion well above the noise, and
 * the whole model (full, m terms) must explain most of the motion. */
static int heart_present(sh_tracker *t, int n, const double *full, int m, const double *trend, int m_trend,
                         double fl, double noise2)
{
    double coef[NC], cov[NC * NC];
    double exh = 0, res = 0, tot = 0;
    for (int mi = 0, q = 0; mi < t->nm && q < RATE_SERIES; mi++) {
        if (!t->m[mi].init) continue;
        for (int a = 0; a < t->dim && q < RATE_SERIES; a++) {
            double *x = t->scratch;
            int valid = gather(t, mi, a, x, n);
            if (valid < 0.6 * n) continue;
            double r = fit_series(x, n, full, m, coef, cov, fl);
            double r0 = fit_series(x, n, trend, m_trend, coef + NC / 2, cov, -1);
            if (r < 0 || r0 < 0) continue;
            double v = 0;
            for (int k = 2; k < 2 + 2 * t->o.heart_harmonics; k++) v += 0.5 * coef[k] * coef[k];
            exh += v;
            res += r * r;
            tot += r0 * r0;
            q++;
        }
    }
    return !(!(tot > 0) || res > 0.5 * tot || exh / RATE_SERIES < 4 * noise2);
}

/* (Re)initialises every marker's filters from a fit of its own history (full, m terms) after the
 * rates changed; was_locked: whether they were locked before. */
static void refit_filters(sh_tracker *t, int n, double ts, const double *full, int m, double fl, double noise2,
                          int was_locked)
{
    double coef[NC], cov[NC * NC];
    double u = t->unit > 0 ? t->unit : 1;
    double tmid = 0.5 * (n - 1) * ts, tn = (n - 1) * ts;
    /* the newest sample is frame hist_last * decim; now is t->frame */
    double now = tn + (t->frame - t->hist_last * t->decim) / t->o.fps;
    double *x = t->scratch; /* reuse: the series are no longer needed */
    for (int mi = 0; mi < t->nm; mi++) {
        marker *mk = &t->m[mi];
        if (!mk->init) continue;
        for (int a = 0; a < t->dim; a++) {
            axis_filter *f = &mk->f[a];
            int valid = gather(t, mi, a, x, n);
            double r = valid >= 2 * (2 + 2 * t->nh + 2 * t->nr)
                           ? fit_series(x, n, full, m, coef, cov, fl)
                           : -1;
            if (r >= 0) {
                double s2 = fmax(r * r, noise2);
                filter_from_fit(t, f, coef, cov, m, s2, now, tmid);
                /* the fit cannot know how the heart will vary: some slack */
                f->P[0] += 4 * noise2;
            } else if (!was_locked) {
                /* too little track: baseline from the last estimate, harmonics unknown */
                double z = f->x[0], pz = f->P[0];
                memset(f, 0, sizeof *f);
                f->x[0] = z;
                f->P[0] = pz + 100 * noise2;
                double amp = 20.0 * u; /* prior amplitude of a harmonic, px */
                for (int k = 0; k < t->nh; k++) {
                    int i = 2 + 2 * k;
                    f->P[i * NS + i] = f->P[(i + 1) * NS + i + 1] = amp * amp;
                }
            }
            /* locked before and too little history: keep the running filter */
        }
    }
}

void trk_estimate_rates(sh_tracker *t)
{
    int n = SH_TRACK_HISTORY;
    if (t->hist_last + 1 < n) n = (int)(t->hist_last + 1);
    double ts = t->decim / t->o.fps;
    if (n * ts < 4.0 || n < 32) return; /* at least 4 s of track */
    double *top[RATE_SERIES];
    int ntop = top_series(t, n, top);
    if (ntop < 1) return;
    double u = t->unit > 0 ? t->unit : 1;
    double noise2 = t->o.meas_sigma * t->o.meas_sigma * u * u, fl = sqrt(noise2);
    double fh = search_rate(t, top, ntop, n, ts, t->o.heart_min_hz, t->o.heart_max_hz, t->o.heart_harmonics);
    int m, m_trend;
    double fr = 0;
    int nr = 0;
    const double *trend = basis_table(t, 1, n, ts, 0, 0, 0, 0, &m_trend);
    if (t->o.resp_harmonics > 0 && n * ts >= 6.0)
        nr = search_resp(t, top, ntop, n, ts, fh, trend, m_trend, noise2, &fr);
    const double *full = basis_table(t, 3, n, ts, fh, t->o.heart_harmonics, fr, nr, &m);
    if (!heart_present(t, n, full, m, trend, m_trend, fl, noise2)) return;
    int restructure = !t->locked || nr != t->nr || fabs(fh - t->fh) > 0.05 * t->fh ||
                      (nr && fabs(fr - t->fr) > 0.1 * t->fr);
    t->fh = fh;
    t->fr = fr;
    t->nh = t->o.heart_harmonics;
    t->nr = nr;
    t->stats.heart_hz = fh;
    t->stats.resp_hz = fr;
    if (!restructure) return;
    t->fresh_fit = 1;
    int was_locked = t->locked;
    t->locked = 1;
    refit_filters(t, n, ts, full, m, fl, noise2, was_locked);
    t->stats.locked = 1;
}
