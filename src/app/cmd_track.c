/* stillheart track: AprilTag detection in the tracker's windows, the Kalman tracker, and the
 * points file of `stillheart warp` (with X,Y,Z when calibrated cameras are given). */
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "stillheart/calib.h"
#include "stillheart/detect.h"
#include "stillheart/log.h"
#include "stillheart/points.h"
#include "stillheart/track.h"
#include "stillheart/y4m.h"

#define MAX_DET SH_TRACK_MAX_DETECTIONS

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart track [OPTIONS] IN.y4m [IN2.y4m [IN3.y4m]] > points.csv\n\n"
        "Tracks the AprilTag markers of a recording and writes the points file of\n"
        "`stillheart warp`: `frame,id,x,y`, one row per marker per frame (pixels of the first\n"
        "camera), and `X,Y,Z` (calibration units) with --cameras. Detection runs in windows\n"
        "around the tracker's predictions, with a full-frame scan spread over frames to find\n"
        "lost markers. A marker hidden for a while is still written (predicted from its own\n"
        "rhythm and its neighbours); one unseen for longer than --lost-after is not.\n\n"
        "Markers: --ids lists them; without it a first pass over the first 10 s (or the whole of\n"
        "a shorter file) keeps every tag seen consistently unless its motion says it is not on\n"
        "the heart: still while its neighbours move, or moving unlike them (on an instrument).\n"
        "What is left out, and why, is said on standard error. Then the recording is tracked\n"
        "from its start with those ids (IN must then be files).\n\n"
        "options:\n"
        "  --cameras FILE     calibration YAML (OpenCV FileStorage): one IN per camera, 3D tracking\n"
        "  --ids LIST         marker ids, e.g. 0-15 or 1,4,7\n"
        "  --family F         tag family (default tag36h11)\n"
        "  --fps F            frame rate when the Y4M header has none (default 30)\n"
        "  --noise PX         detection noise, px (default 0.3)\n"
        "  --lost-after S     seconds unseen before a marker is dropped (default 2)\n"
        "  --spatial off|fuse occluded markers from time only, or also from neighbours (default fuse)\n"
        "  --measured-only    write only markers detected in that frame\n"
        "  --stats            tracking figures on standard error at the end (and without --ids,\n"
        "                     why each tag was kept)\n"
        "  --help             this text\n");
}

static int parse_ids(const char *text, int *ids, int *n)
{
    *n = 0;
    const char *p = text;
    while (*p) {
        char *end;
        long a = strtol(p, &end, 10), b;
        if (end == p || a < 0 || a > 1000000) return 0;
        p = end;
        b = a;
        if (*p == '-') {
            p++;
            b = strtol(p, &end, 10);
            if (end == p || b < a || b > 1000000) return 0;
            p = end;
        }
        for (long v = a; v <= b; v++) {
            if (*n >= SH_TRACK_MAX_MARKERS) return 0;
            ids[(*n)++] = (int)v;
        }
        if (*p == ',') p++;
        else if (*p) return 0;
    }
    return *n > 0;
}

typedef struct {
    const char *in[SH_TRACK_MAX_CAMERAS];
    int ncam;
    sh_calib calib;
    int have_calib;
    sh_detector *det;
    sh_track_options topts;
    int measured_only, stats;
} track_job;

/* Same id, same place (within 1 px): one tag found by two overlapping windows. */
static int dedupe(sh_detection *d, int n)
{
    int w = 0;
    for (int i = 0; i < n; i++) {
        int dup = 0;
        for (int j = 0; j < w && !dup; j++)
            dup = d[j].id == d[i].id && fabs(d[j].cx - d[i].cx) < 1 && fabs(d[j].cy - d[i].cy) < 1;
        if (!dup) d[w++] = d[i];
    }
    return w;
}

/* One pass: max_frames (< 0: all). out NULL: no output; judged (when not NULL) gets the verdicts
 * on every tag seen (sh_tracker_judge_ids) at the end. Returns 0 on success. */
static int run_pass(track_job *job, int max_frames, FILE *out, sh_track_id *judged, int *njudged)
{
    int rc = 1;
    sh_y4m_reader *rd[SH_TRACK_MAX_CAMERAS] = {0};
    sh_image img[SH_TRACK_MAX_CAMERAS];
    memset(img, 0, sizeof img);
    sh_tracker *t = NULL;
    static sh_detection dets[SH_TRACK_MAX_CAMERAS][MAX_DET];
    sh_window win[SH_TRACK_MAX_CAMERAS][SH_TRACK_MAX_MARKERS + 1];
    sh_track_estimate est[SH_TRACK_MAX_MARKERS];
    static sh_point rows[SH_TRACK_MAX_MARKERS];
    int width = 0, height = 0;
    double fps = 0;
    for (int c = 0; c < job->ncam; c++) {
        if (sh_y4m_reader_open(job->in[c], &rd[c]) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto done;
        }
        const sh_y4m_header *h = sh_y4m_reader_header(rd[c]);
        if (c == 0) {
            width = h->width;
            height = h->height;
            if (h->fps_num > 0 && h->fps_den > 0) fps = (double)h->fps_num / h->fps_den;
        } else if (h->width != width || h->height != height) {
            sh_log_error("%s is %dx%d, %s is %dx%d: the cameras must match",
                         job->in[c], h->width, h->height, job->in[0], width, height);
            goto done;
        }
        if (sh_image_create(&img[c], h->format, h->width, h->height) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto done;
        }
    }
    if (job->have_calib && (job->calib.width != width || job->calib.height != height))
        sh_log_warn("warning: calibration is for %dx%d, video is %dx%d",
                    job->calib.width, job->calib.height, width, height);
    sh_track_options o = job->topts;
    if (fps > 0 && o.fps <= 0) o.fps = fps;
    if (o.fps <= 0) o.fps = 30;
    o.width = width;
    o.height = height;
    if (sh_tracker_create(&o, job->have_calib ? &job->calib : NULL, &t) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto done;
    }
    for (int f = 0; max_frames < 0 || f < max_frames; f++) {
        int eof = 0;
        for (int c = 0; c < job->ncam; c++) {
            sh_status st = sh_y4m_reader_read(rd[c], &img[c]);
            if (st == SH_EEOF) {
                if (c > 0 && !eof)
                    sh_log_warn("warning: %s ends at frame %d before %s",
                                job->in[c], f, job->in[0]);
                eof = 1;
            } else if (st != SH_OK) {
                sh_log_error("%s", sh_error_message());
                goto done;
            }
        }
        if (eof) break;
        if (sh_tracker_predict(t, f) != SH_OK) goto fail;
        const sh_detection *dp[SH_TRACK_MAX_CAMERAS];
        int count[SH_TRACK_MAX_CAMERAS];
        for (int c = 0; c < job->ncam; c++) {
            int nw = 0, nb = 0, n = 0;
            if (sh_tracker_windows(t, c, win[c], SH_TRACK_MAX_MARKERS, &nw) != SH_OK) goto fail;
            if (sh_tracker_reacquire(t, c, &win[c][nw], &nb) != SH_OK) goto fail;
            sh_status st;
            if (f == 0 || nw == 0) st = sh_detector_detect(job->det, &img[c], dets[c], MAX_DET, &n);
            else st = sh_detector_detect_windows(job->det, &img[c], win[c], nw + nb, dets[c], MAX_DET, &n);
            if (st == SH_OK && f > 0 && nw > 0 && sh_tracker_rescan(t, c, dets[c], n < MAX_DET ? n : MAX_DET))
                st = sh_detector_detect(job->det, &img[c], dets[c], MAX_DET, &n);
            if (st != SH_OK) {
                sh_log_error("%s: frame %d: %s", job->in[c], f, sh_error_message());
                goto done;
            }
            if (n > MAX_DET) n = MAX_DET;
            count[c] = dedupe(dets[c], n);
            dp[c] = dets[c];
        }
        if (sh_tracker_update(t, dp, count, job->ncam) != SH_OK) goto fail;
        if (out) {
            int n = sh_tracker_estimates(t, est, SH_TRACK_MAX_MARKERS), nr = 0;
            for (int k = 0; k < n; k++) {
                const sh_track_estimate *e = &est[k];
                if (!e->confirmed || e->status == SH_TRACK_LOST || !e->in_view[0]) continue;
                if (job->measured_only && e->status != SH_TRACK_MEASURED) continue;
                sh_point *p = &rows[nr++];
                p->frame = f;
                p->id = e->id;
                p->x = e->xy[0][0];
                p->y = e->xy[0][1];
                p->X = e->dim == 3 ? e->pos[0] : NAN;
                p->Y = e->dim == 3 ? e->pos[1] : NAN;
                p->Z = e->dim == 3 ? e->pos[2] : NAN;
            }
            if (f == 0 && fprintf(out, "frame,id,x,y%s\n", job->have_calib ? ",X,Y,Z" : "") < 0) goto wfail;
            for (int k = 0; k < nr; k++) {
                const sh_point *p = &rows[k];
                int w = job->have_calib
                            ? fprintf(out, "%d,%d,%.4f,%.4f,%.5f,%.5f,%.5f\n", p->frame, p->id, p->x, p->y, p->X, p->Y, p->Z)
                            : fprintf(out, "%d,%d,%.4f,%.4f\n", p->frame, p->id, p->x, p->y);
                if (w < 0) goto wfail;
            }
        }
    }
    if (judged) *njudged = sh_tracker_judge_ids(t, judged, SH_TRACK_MAX_MARKERS);
    if (job->stats && out) {
        sh_track_stats s;
        sh_tracker_stats(t, &s);
        sh_log_info("%ld frames, heart %.3f Hz, respiration %.3f Hz; detections used %ld, "
                    "gated %ld, duplicated ids %ld, unknown ids %ld, inconsistent 3D %ld, taken on their "
                    "neighbours' agreement %ld; markers lost %ld; camera moved in %ld frames",
                    s.frames, s.heart_hz, s.resp_hz, s.accepted, s.gated, s.duplicates, s.unknown,
                    s.inconsistent, s.jumped, s.lost, s.camera_moves);
        sh_track_calibration cc;
        sh_tracker_calibration(t, &cc);
        if (cc.samples)
            sh_log_info("calibration: reprojection median %.3f px over the last %d markers seen by two or more "
                        "cameras, camera %d's views %.3f px, %.0f %% behind a camera",
                        cc.median_px, cc.samples, cc.worst_camera, cc.worst_px, 100 * cc.failed);
    }
    rc = 0;
    goto done;
wfail:
    sh_log_error("writing the points: write error");
    goto done;
fail:
    sh_log_error("%s", sh_error_message());
done:
    sh_tracker_destroy(t);
    for (int c = 0; c < job->ncam; c++) {
        sh_image_destroy(&img[c]);
        if (rd[c]) sh_y4m_reader_close(rd[c]);
    }
    return rc;
}

/* The first pass's verdicts on standard error: what is kept, and every tag left out or kept
 * without a comparison (all: every tag), with why. The kept ids into ids; returns their count. */
static int report_ids(const sh_track_id *v, int n, int *ids, const char *in, int all)
{
    char list[1024] = "", why[256];
    int nk = 0;
    size_t len = 0;
    for (int k = 0; k < n; k++) {
        if (!v[k].keep) continue;
        ids[nk++] = v[k].id;
        /* ranges: 0-15,17 */
        int run_end = k + 1 < n && v[k + 1].keep && v[k + 1].id == v[k].id + 1;
        int run_in = nk > 1 && ids[nk - 2] == v[k].id - 1;
        if (run_in && run_end) continue;
        if (len < sizeof list)
            len += (size_t)snprintf(list + len, sizeof list - len, "%s%d", run_in ? "-" : nk > 1 ? "," : "", v[k].id);
    }
    sh_log_info("markers found in %s: %d of the %d tags seen (ids %s)", in, nk, n, nk ? list : "none");
    for (int k = 0; k < n; k++) {
        if (v[k].keep && v[k].verdict == SH_TRACK_ID_KEPT && !all) continue;
        sh_track_id_text(&v[k], why, sizeof why);
        if (v[k].keep) sh_log_info("tag %d kept as a marker, %s", v[k].id, why);
        else sh_log_warn("warning: tag %d left out, %s", v[k].id, why);
    }
    return nk;
}

int cmd_track(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart track", SH_LOG_INFO);
    static const struct option longopts[] = {
        {"cameras", required_argument, 0, 'c'}, {"ids", required_argument, 0, 'i'},
        {"family", required_argument, 0, 'f'},  {"fps", required_argument, 0, 'r'},
        {"noise", required_argument, 0, 'n'},   {"lost-after", required_argument, 0, 'l'},
        {"spatial", required_argument, 0, 's'}, {"measured-only", no_argument, 0, 'm'},
        {"stats", no_argument, 0, 'S'},         {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    track_job job;
    memset(&job, 0, sizeof job);
    sh_track_options_default(&job.topts);
    const char *calib_path = NULL, *family = NULL;
    int ids[SH_TRACK_MAX_MARKERS], nids = 0;
    double fps = 0;
    optind = 1;
    int ch;
    while ((ch = getopt_long(argc, argv, "", longopts, NULL)) != -1) {
        switch (ch) {
        case 'c': calib_path = optarg; break;
        case 'i':
            if (!parse_ids(optarg, ids, &nids)) {
                fprintf(stderr, "--ids: '%s' is not a list like 0-15 or 1,4,7 (at most %d ids)\n",
                        optarg, SH_TRACK_MAX_MARKERS);
                return 2;
            }
            break;
        case 'f': family = optarg; break;
        case 'r': if (!app_parse_double("--fps", optarg, 0.1, 1000, &fps)) return 2; break;
        case 'n': if (!app_parse_double("--noise", optarg, 0.01, 20, &job.topts.meas_sigma)) return 2; break;
        case 'l': if (!app_parse_double("--lost-after", optarg, 0.1, 60, &job.topts.lost_after)) return 2; break;
        case 's':
            if (!strcmp(optarg, "off")) job.topts.spatial = SH_SPATIAL_OFF;
            else if (!strcmp(optarg, "fuse")) job.topts.spatial = SH_SPATIAL_FUSE;
            else {
                fprintf(stderr, "--spatial: off or fuse, not '%s'\n", optarg);
                return 2;
            }
            break;
        case 'm': job.measured_only = 1; break;
        case 'S': job.stats = 1; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    job.ncam = argc - optind;
    if (job.ncam < 1 || job.ncam > SH_TRACK_MAX_CAMERAS) {
        usage(stderr);
        return 2;
    }
    for (int c = 0; c < job.ncam; c++) job.in[c] = argv[optind + c];
    if (calib_path) {
        if (sh_calib_read(calib_path, &job.calib) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 1;
        }
        if (job.calib.num_cameras != job.ncam) {
            sh_log_error("%s has %d cameras, %d videos given", calib_path,
                         job.calib.num_cameras, job.ncam);
            return 2;
        }
        job.have_calib = job.ncam > 1;
        if (job.ncam == 1)
            sh_log_info("one camera: tracking in pixels (the calibration's "
                            "3D needs two or more)");
    } else if (job.ncam > 1) {
        sh_log_error("%d videos need --cameras (their calibration)", job.ncam);
        return 2;
    }
    job.topts.fps = fps;
    sh_detector_options dopts;
    sh_detector_options_default(&dopts);
    if (family) dopts.family = family;
    if (sh_detector_create(&dopts, &job.det) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    int rc = 0;
    if (nids == 0) {
        for (int c = 0; c < job.ncam; c++)
            if (!strcmp(job.in[c], "-")) {
                sh_log_error("standard input needs --ids (the markers are found "
                                "in a first pass over the file)");
                sh_detector_destroy(job.det);
                return 2;
            }
        /* first pass: which tags are markers on the heart (a short file is judged whole) */
        double f0 = fps > 0 ? fps : 30;
        sh_track_id judged[SH_TRACK_MAX_MARKERS];
        int nj = 0;
        if (run_pass(&job, (int)(f0 * 10), NULL, judged, &nj) != 0) rc = 1;
        else if ((nids = report_ids(judged, nj, ids, job.in[0], job.stats)) == 0) {
            sh_log_error("no tag seen consistently in the first 10 s of %s (give the markers with --ids)",
                         job.in[0]);
            rc = 1;
        }
    }
    if (rc == 0) {
        job.topts.ids = ids;
        job.topts.num_ids = nids;
        rc = run_pass(&job, -1, stdout, NULL, NULL);
        if (rc == 0 && fflush(stdout) != 0) {
            sh_log_error("writing the points: write error");
            rc = 1;
        }
    }
    sh_detector_destroy(job.det);
    return rc;
}
