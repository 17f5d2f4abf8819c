/* Heartbeat and respiration rates: a harmonic-sum periodogram over all markers' recent tracks,
 * refined, and least-squares series fits. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

static double search_rate(double *const *x, int ns, int n, double ts, double lo, double hi, int K)
{
    double nyq = 0.5 / ts;
    if (hi > nyq * 0.95) hi = nyq * 0.95;
    double span = n * ts;
    double step = 1.0 / (4 * span);
    double best = lo, bestv = -1;
    for (double f = lo; f <= hi + 1e-12; f += step) {
        double v = harmonic_sum(x, ns, n, ts, f, K, nyq);
        if (v > bestv) {
            bestv = v;
            best = f;
        }
    }
    /* golden section around the best grid point */
    double a = fmax(lo, best - step), b = fmin(hi, best + step);
    const double g = 0.6180339887498949;
    double c = b - g * (b - a), d = a + g * (b - a);
    double fc = harmonic_sum(x, ns, n, ts, c, K, nyq), fd = harmonic_sum(x, ns, n, ts, d, K, nyq);
    for (int it = 0; it < 30; it++) {
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

/* Cholesky solve of the m x m SPD system A c = b (A overwritten); 0 on failure. */
static int chol_solve(double *A, double *b, int m, double *inv)
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

/* Basis of the LS fit at sample j: 1, trend, heart cos/sin pairs, resp cos/sin pairs. */
static int fit_basis(double tj, double tmid, double fh, int nh, double fr, int nr, double *phi)
{
    int m = 0;
    phi[m++] = 1;
    phi[m++] = tj - tmid;
    for (int k = 1; k <= nh; k++) {
        phi[m++] = cos(2 * PI * k * fh * tj);
        phi[m++] = sin(2 * PI * k * fh * tj);
    }
    for (int k = 1; k <= nr; k++) {
        phi[m++] = cos(2 * PI * k * fr * tj);
        phi[m++] = sin(2 * PI * k * fr * tj);
    }
    return m;
}

#define FIT_PASSES 4

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* median of v[0..n-1] (sorts v; at most SH_TRACK_HISTORY values, only when the rates change) */
static double median_of(double *v, int n)
{
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Least squares fit of one series; coef (m), cov (m x m, unscaled (A^T A)^-1), returns the residual
 * RMS of the inliers or -1 when the fit is impossible. Robust: refitted without the samples off by
 * more than 3 robust standard deviations (1.4826 x the median absolute residual, never less than
 * floor), so the wrong detections accepted before the rates were known do not bend the model. */
static double fit_series(const double *x, int n, double ts, double fh, int nh, double fr, int nr,
                         double *coef, double *cov, int *mout, double floor)
{
    unsigned char out[SH_TRACK_HISTORY];
    memset(out, 0, sizeof out);
    int m = 2 + 2 * nh + 2 * nr;
    double tmid = 0.5 * (n - 1) * ts, rms = -1;
    for (int pass = 0; pass < FIT_PASSES; pass++) {
        double A[NC * NC] = {0}, b[NC] = {0}, phi[NC];
        int cnt = 0;
        for (int j = 0; j < n; j++) {
            if (isnan(x[j]) || out[j]) continue;
            fit_basis(j * ts, tmid, fh, nh, fr, nr, phi);
            for (int a = 0; a < m; a++) {
                b[a] += phi[a] * x[j];
                for (int c = 0; c <= a; c++) A[a * m + c] += phi[a] * phi[c];
            }
            cnt++;
        }
        if (cnt < 2 * m) return -1;
        for (int a = 0; a < m; a++)
            for (int c = 0; c < a; c++) A[c * m + a] = A[a * m + c];
        if (!chol_solve(A, b, m, cov)) return -1;
        memcpy(coef, b, sizeof(double) * m);
        double ss = 0;
        for (int j = 0; j < n; j++) {
            if (isnan(x[j]) || out[j]) continue;
            fit_basis(j * ts, tmid, fh, nh, fr, nr, phi);
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
            fit_basis(j * ts, tmid, fh, nh, fr, nr, phi);
            double v = 0;
            for (int a = 0; a < m; a++) v += phi[a] * coef[a];
            res[nres++] = fabs(x[j] - v);
        }
        double sorted[SH_TRACK_HISTORY];
        memcpy(sorted, res, sizeof(double) * nres);
        double lim = 3 * fmax(1.4826 * median_of(sorted, nres), floor);
        int changed = 0;
        for (int j = 0, q = 0; j < n; j++) {
            if (isnan(x[j])) continue;
            unsigned char o = res[q++] > lim;
            if (o != out[j]) changed = 1;
            out[j] = o;
        }
        if (!changed) break;
    }
    *mout = m;
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

void trk_estimate_rates(sh_tracker *t)
{
    int n = SH_TRACK_HISTORY;
    if (t->hist_last + 1 < n) n = (int)(t->hist_last + 1);
    double ts = t->decim / t->o.fps;
    if (n * ts < 4.0 || n < 32) return; /* at least 4 s of track */
    /* candidate series: markers with >= 60% valid samples, detrended; keep the largest */
    double *ser[MAXM * 3];
    double var[MAXM * 3];
    int owner[MAXM * 3];
    int ns = 0;
    for (int mi = 0; mi < t->nm; mi++) {
        if (!t->m[mi].init) continue;
        for (int a = 0; a < t->dim; a++) {
            double *x = t->scratch + (size_t)ns * SH_TRACK_HISTORY;
            int valid = gather(t, mi, a, x, n);
            if (valid < 0.6 * n) continue;
            /* remove mean and linear trend */
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
            var[ns] = v / s0;
            owner[ns] = mi;
            ser[ns++] = x;
        }
    }
    if (ns < 1) return;
    /* the RATE_SERIES series of largest variance */
    double *top[RATE_SERIES];
    int ntop = 0;
    {
        unsigned char used[MAXM * 3] = {0};
        for (; ntop < RATE_SERIES && ntop < ns; ntop++) {
            int bi = -1;
            for (int i = 0; i < ns; i++)
                if (!used[i] && (bi < 0 || var[i] > var[bi])) bi = i;
            used[bi] = 1;
            top[ntop] = ser[bi];
        }
    }
    double u = t->unit > 0 ? t->unit : 1;
    double noise2 = t->o.meas_sigma * t->o.meas_sigma * u * u, fl = sqrt(noise2);
    double fh = search_rate(top, ntop, n, ts, t->o.heart_min_hz, t->o.heart_max_hz, t->o.heart_harmonics);
    double coef[NC], cov[NC * NC];
    int m;
    double fr = 0;
    int nr = 0;
    if (t->o.resp_harmonics > 0 && n * ts >= 6.0) {
        /* respiration on the residual of the heart fit */
        double tmid = 0.5 * (n - 1) * ts, phi[NC];
        for (int i = 0; i < ntop; i++) {
            double r = fit_series(top[i], n, ts, fh, t->o.heart_harmonics, 0, 0, coef, cov, &m, -1);
            if (r < 0) continue;
            for (int j = 0; j < n; j++) {
                if (isnan(top[i][j])) continue;
                fit_basis(j * ts, tmid, fh, t->o.heart_harmonics, 0, 0, phi);
                double v = 0;
                for (int k = 2; k < m; k++) v += phi[k] * coef[k];
                top[i][j] -= v;
            }
        }
        double lo = fmax(t->o.resp_min_hz, 1.5 / (n * ts));
        if (lo < t->o.resp_max_hz) {
            double f = search_rate(top, ntop, n, ts, lo, t->o.resp_max_hz, t->o.resp_harmonics);
            double exr = 0, totr = 0;
            for (int i = 0; i < ntop; i++) {
                double r0 = fit_series(top[i], n, ts, fh, 0, 0, 0, coef, cov, &m, -1);
                double r1 = fit_series(top[i], n, ts, fh, 0, f, t->o.resp_harmonics, coef, cov, &m, -1);
                if (r0 < 0 || r1 < 0) continue;
                exr += r0 * r0 - r1 * r1;
                totr += r0 * r0;
            }
            if (totr > 0 && exr > 0.3 * totr && exr / ntop > 4 * noise2) {
                fr = f;
                nr = t->o.resp_harmonics;
            }
        }
    }
    /* is there a heartbeat at all? the heart harmonics must carry motion well above the noise, and
     * the whole model must explain most of the motion */
    double exh = 0, res = 0, tot = 0;
    for (int mi = 0, q = 0; mi < t->nm && q < RATE_SERIES; mi++) {
        if (!t->m[mi].init) continue;
        for (int a = 0; a < t->dim && q < RATE_SERIES; a++) {
            double *x = t->scratch;
            int valid = gather(t, mi, a, x, n);
            if (valid < 0.6 * n) continue;
            double r = fit_series(x, n, ts, fh, t->o.heart_harmonics, fr, nr, coef, cov, &m, fl);
            double r0 = fit_series(x, n, ts, fh, 0, 0, 0, coef + NC / 2, cov, &m, -1);
            if (r < 0 || r0 < 0) continue;
            double v = 0;
            for (int k = 2; k < 2 + 2 * t->o.heart_harmonics; k++) v += 0.5 * coef[k] * coef[k];
            exh += v;
            res += r * r;
            tot += r0 * r0;
            q++;
        }
    }
    (void)owner;
    if (!(tot > 0) || res > 0.5 * tot || exh / RATE_SERIES < 4 * noise2) return;
    int restructure = !t->locked || nr != t->nr || fabs(fh - t->fh) > 0.05 * t->fh ||
                      (nr && fabs(fr - t->fr) > 0.1 * t->fr);
    t->fh = fh;
    t->fr = fr;
    t->nh = t->o.heart_harmonics;
    t->nr = nr;
    t->stats.heart_hz = fh;
    t->stats.resp_hz = fr;
    if (!restructure) return;
    /* (re)initialise every marker's filters from a fit of its own history */
    int was_locked = t->locked;
    t->locked = 1;
    double tmid = 0.5 * (n - 1) * ts, tn = (n - 1) * ts;
    /* the newest sample is frame hist_last * decim; now is t->frame */
    double now = tn + (t->frame - t->hist_last * t->decim) / t->o.fps;
    double *x = t->scratch; /* reuse: the series are no longer needed */
    (void)owner;
    for (int mi = 0; mi < t->nm; mi++) {
        marker *mk = &t->m[mi];
        if (!mk->init) continue;
        for (int a = 0; a < t->dim; a++) {
            axis_filter *f = &mk->f[a];
            int valid = gather(t, mi, a, x, n);
            double r = valid >= 2 * (2 + 2 * t->nh + 2 * t->nr)
                           ? fit_series(x, n, ts, fh, t->nh, fr, t->nr, coef, cov, &m, fl)
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
    t->stats.locked = 1;
}
