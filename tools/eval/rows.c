/* --landmark-rows: the landmark rows of a points file (`stillheart track --landmarks`, ids from
 * SH_LANDMARK_ID_BASE) judged against the phantom's truth. Each landmark's reference row locates
 * its material point in the reference frame; every later row is compared with where the truth
 * puts that point in that frame: the row's x, y in the camera the points are of, and with a
 * calibration its X, Y, Z projected into every camera that sees the point then (the reference
 * frame's rows included: their X, Y, Z is the landmark's reference in 3D). An error across the
 * rig's epipolar lines shows in one camera, one along them (depth) in the others. A landmark
 * chosen where the reference frame showed the instrument or blood over the tissue is judged, as
 * stillheart-eval --landmarks judges it, against the tissue behind its pixel, whether the cover
 * is still there or not (never hidden: it was never seen), and counted apart. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "eval.h"
#include "stillheart/camera.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"

typedef struct {
    float *err;
    long long n, cap, over;
    double sum, max;
} errors;

static int add(errors *e, double v)
{
    if (e->n == e->cap) {
        long long cap = e->cap ? 2 * e->cap : 4096;
        float *p = realloc(e->err, sizeof(float) * (size_t)cap);
        if (!p) return 0;
        e->err = p, e->cap = cap;
    }
    e->err[e->n++] = (float)v;
    e->sum += v;
    e->over += v > 1;
    if (v > e->max) e->max = v;
    return 1;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Nearest rank, as the geometric error's percentile. */
static double p99(errors *e)
{
    if (e->n == 0) return NAN;
    qsort(e->err, (size_t)e->n, sizeof(float), cmp_float);
    long long k = (long long)ceil(0.99 * (double)e->n) - 1;
    return e->err[k < 0 ? 0 : k];
}

typedef struct {
    long long rows, unjudged, hidden;
    errors e2, e3; /* the rows' x, y; their X, Y, Z's worst camera */
    /* landmarks chosen on a cover; their rows after the reference, and of those over 1 px in x, y;
     * their rows with X, Y, Z (the reference's too) over 1 px in the worst camera */
    int chosen_covered;
    long long rows_covered, over_covered, over3_covered;
} judged;

/* One row against the truth (covered: the landmark was chosen on a cover, and is judged against
 * the tissue behind it in every camera, seen or not): 0 when out of memory. */
static int judge(const phantom_truth *truth, const sh_calib *calib, int camera, int reference, double u, double v,
                 int covered, const sh_point *r, judged *j)
{
    if (r->frame != reference) {
        j->rows++;
        j->rows_covered += covered;
        double gx, gy;
        if (!covered && !phantom_truth_visible(truth, camera, r->frame, u, v)) {
            j->hidden++;
            return 1;
        }
        if (phantom_truth_project(truth, camera, r->frame, u, v, &gx, &gy) == SH_OK) {
            double e = hypot(r->x - gx, r->y - gy);
            if (!add(&j->e2, e)) return 0;
            j->over_covered += covered && e > 1;
        }
    }
    if (!calib || !isfinite(r->X)) return 1;
    double worst = -1, X[3] = {r->X, r->Y, r->Z};
    for (int c = 0; c < calib->num_cameras; c++) {
        double uv[2], gx, gy;
        if ((!covered && !phantom_truth_visible(truth, c, r->frame, u, v)) ||
            phantom_truth_project(truth, c, r->frame, u, v, &gx, &gy) != SH_OK)
            continue;
        double d = sh_camera_project(&calib->cam[c], X, uv, NULL) == SH_OK ? hypot(uv[0] - gx, uv[1] - gy) : INFINITY;
        if (d > worst) worst = d;
    }
    j->over3_covered += covered && worst > 1;
    return worst < 0 || add(&j->e3, worst);
}

static void print_errors(sh_cli_json *j, const char *name, errors *e, int json)
{
    double mean = e->n ? e->sum / (double)e->n : NAN, q = p99(e);
    if (json) {
        sh_cli_json_object(j, name);
        sh_cli_json_int(j, "rows", e->n);
        sh_cli_json_number(j, "mean", mean);
        sh_cli_json_number(j, "p99", q);
        sh_cli_json_number(j, "max", e->n ? e->max : NAN);
        sh_cli_json_int(j, "over_1px", e->over);
        sh_cli_json_end(j);
    } else {
        printf("  %s: %lld rows, mean %.3f px, p99 %.3f, max %.3f, over 1 px %lld\n", name, e->n, mean, q,
               e->n ? e->max : NAN, e->over);
    }
}

int eval_rows_main(const char *truth_dir, const char *points_path, const sh_calib *calib, int camera, int reference,
                   int json)
{
    sh_points points;
    phantom_truth *truth = NULL;
    if (sh_points_read(points_path, &points) != SH_OK || sh_points_need_2d(&points, points_path) != SH_OK) {
        sh_log_error("--points: %s", sh_error_message());
        return 1;
    }
    if (phantom_truth_open(truth_dir, &truth) != SH_OK) {
        sh_log_error("--truth: %s", sh_error_message());
        sh_points_destroy(&points);
        return 1;
    }
    int nref, rc = 0, landmarks = 0;
    const sh_point *ref = sh_points_frame(&points, reference, &nref);
    judged j = {0};
    /* each landmark's material point, from its reference row (NAN: no truth there) */
    int nlm = 0;
    for (int k = 0; k < nref; k++) nlm += ref[k].id >= SH_LANDMARK_ID_BASE;
    double *uv = malloc(sizeof(double) * 2 * (size_t)(nlm + 1));
    int *ids = malloc(sizeof(int) * (size_t)(nlm + 1));
    uint8_t *covered = calloc((size_t)(nlm + 1), 1);
    if (!uv || !ids || !covered) rc = 1;
    for (int k = 0; k < nref && !rc; k++) {
        if (ref[k].id < SH_LANDMARK_ID_BASE) continue;
        ids[landmarks] = ref[k].id;
        double *p = &uv[2 * landmarks];
        if (phantom_truth_locate(truth, camera, reference, ref[k].x, ref[k].y, &p[0], &p[1]) != SH_OK) p[0] = NAN;
        else j.chosen_covered += covered[landmarks] = !phantom_truth_visible(truth, camera, reference, p[0], p[1]);
        landmarks++;
    }
    for (int f = reference; f <= points.max_frame && !rc; f++) {
        int n;
        const sh_point *rows = sh_points_frame(&points, f, &n);
        for (int k = 0, l = 0; k < n && !rc; k++) {
            if (rows[k].id < SH_LANDMARK_ID_BASE) continue;
            while (l < landmarks && ids[l] < rows[k].id) l++; /* both sorted by id */
            if (l == landmarks || ids[l] != rows[k].id || isnan(uv[2 * l])) {
                j.unjudged++;
                continue;
            }
            rc = !judge(truth, calib, camera, reference, uv[2 * l], uv[2 * l + 1], covered[l], &rows[k], &j);
        }
    }
    if (rc) {
        sh_log_error("--landmark-rows: out of memory");
    } else if (json) {
        sh_cli_json o;
        sh_cli_json_start(&o, stdout);
        sh_cli_json_object(&o, NULL);
        sh_cli_json_int(&o, "landmarks", landmarks);
        sh_cli_json_int(&o, "rows", j.rows);
        sh_cli_json_int(&o, "hidden", j.hidden);
        sh_cli_json_int(&o, "unjudged", j.unjudged);
        sh_cli_json_object(&o, "covered");
        sh_cli_json_int(&o, "landmarks", j.chosen_covered);
        sh_cli_json_int(&o, "rows", j.rows_covered);
        sh_cli_json_int(&o, "image_over_1px", j.over_covered);
        if (calib) sh_cli_json_int(&o, "reprojected_over_1px", j.over3_covered);
        else sh_cli_json_null(&o, "reprojected_over_1px");
        sh_cli_json_end(&o);
        print_errors(&o, "image", &j.e2, 1);
        if (calib) print_errors(&o, "reprojected", &j.e3, 1);
        else sh_cli_json_null(&o, "reprojected");
        sh_cli_json_end(&o);
    } else {
        printf("%s: %d landmarks in frame %d, %lld rows after it: %lld the truth says are hidden, %lld without a "
               "truth\n", points_path, landmarks, reference, j.rows, j.hidden, j.unjudged);
        printf("  chosen where something covered the tissue in frame %d: %d, their rows after it %lld, more than 1 px "
               "from the tissue behind: %lld in x, y", reference, j.chosen_covered, j.rows_covered, j.over_covered);
        if (calib) printf(", %lld in X, Y, Z (frame %d's rows too)", j.over3_covered, reference);
        printf("\n");
        char what[96];
        snprintf(what, sizeof what, "x, y in camera %d", camera);
        print_errors(NULL, what, &j.e2, 0);
        snprintf(what, sizeof what, "X, Y, Z in the worst camera (frame %d's rows too)", reference);
        if (calib) print_errors(NULL, what, &j.e3, 0);
    }
    free(uv), free(ids), free(covered);
    free(j.e2.err), free(j.e3.err);
    phantom_truth_close(truth);
    sh_points_destroy(&points);
    return rc;
}
