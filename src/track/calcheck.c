/* Does the calibration fit what the cameras see? Every marker detected once by two or more cameras
 * of a frame is triangulated from all of those views, before any gate, and each view's
 * reprojection error goes into a window of the last CAL_WINDOW such markers. The tracker's own triangulations
 * cannot tell: they come after the gate, which a wrong calibration has already bent (it gates away
 * the views that disagree), and with three cameras they fall back on the best pair, which two
 * swapped cameras can still form.
 *
 * A correct calibration leaves the detector's noise (a tenth of a pixel on the phantom, docs/3d.md
 * "Is the calibration right?"); two swapped cameras leave pixels; a point that lands behind a
 * camera counts as an infinite error. The medians make a few bad detections (a partly hidden
 * tag) harmless and a calibration that is wrong for most markers plain. */
#include <math.h>
#include <string.h>

#include "track_internal.h"

void trk_calib_observe(sh_tracker *t, const sh_detection *const *det, int num_cameras)
{
    if (t->dim != 3 || num_cameras < 2) return;
    for (int i = 0; i < t->nm; i++) {
        const marker *mk = &t->m[i];
        const sh_calib_camera *vc[MAXC];
        double uv[2 * MAXC];
        int cam_of[MAXC], nv = 0;
        for (int c = 0; c < num_cameras; c++) {
            if (mk->ndet[c] != 1) continue;
            const sh_detection *d = &det[c][mk->det[c]];
            vc[nv] = t->cams[c];
            uv[2 * nv] = d->cx;
            uv[2 * nv + 1] = d->cy;
            cam_of[nv++] = c;
        }
        if (nv < 2) continue;
        sh_triangulation tr;
        int ok = sh_camera_triangulate(vc, uv, nv, t->o.meas_sigma, 5, &tr) == SH_OK;
        int q = t->cal_next;
        t->cal_next = (t->cal_next + 1) % CAL_WINDOW;
        if (t->cal_count < CAL_WINDOW) t->cal_count++;
        t->cal_rms[q] = ok ? tr.rms : INFINITY;
        for (int c = 0; c < MAXC; c++) t->cal_view[c][q] = NAN; /* not seen by camera c */
        for (int v = 0; v < nv; v++) {
            double p[2];
            t->cal_view[cam_of[v]][q] = ok && sh_camera_project(vc[v], tr.X, p, NULL) == SH_OK
                                            ? hypot(p[0] - uv[2 * v], p[1] - uv[2 * v + 1]) : INFINITY;
        }
    }
}

void sh_tracker_calibration(const sh_tracker *t, sh_track_calibration *out)
{
    memset(out, 0, sizeof *out);
    out->worst_camera = -1;
    if (!t || t->dim != 3) return;
    int n = t->cal_count;
    out->samples = n;
    if (n == 0) return;
    double v[CAL_WINDOW];
    int failed = 0;
    for (int k = 0; k < n; k++) failed += isinf(t->cal_rms[k]);
    out->failed = (double)failed / n;
    memcpy(v, t->cal_rms, sizeof(double) * (size_t)n);
    out->median_px = trk_median(v, n);
    for (int c = 0; c < t->ncam; c++) {
        int m = 0;
        for (int k = 0; k < n; k++)
            if (!isnan(t->cal_view[c][k])) v[m++] = t->cal_view[c][k];
        double med = trk_median(v, m);
        if (m && (out->worst_camera < 0 || med > out->worst_px)) {
            out->worst_camera = c;
            out->worst_px = med;
        }
    }
}
