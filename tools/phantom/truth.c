/* Ground-truth queries: pixel -> material point by Newton on the distorted projection, material
 * point -> pixel by the same phantom_surface()/phantom_project() the renderer draws with. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "phantom.h"

struct phantom_truth {
    phantom_model model;
};

sh_status phantom_truth_open(const char *dir, phantom_truth **out)
{
    *out = NULL;
    char path[4096];
    if (snprintf(path, sizeof path, "%s/%s", dir, PHANTOM_PARAMS_FILE) >= (int)sizeof path)
        return sh_error_set(SH_EINVAL, "%s: path too long", dir);
    phantom_truth *t = calloc(1, sizeof *t);
    if (!t) return sh_error_set(SH_ENOMEM, "out of memory");
    sh_status st = phantom_model_read(path, &t->model);
    if (st != SH_OK) {
        free(t);
        return st;
    }
    *out = t;
    return SH_OK;
}

void phantom_truth_close(phantom_truth *truth)
{
    free(truth);
}

const phantom_model *phantom_truth_model(const phantom_truth *truth)
{
    return &truth->model;
}

static sh_status check_cam(const phantom_model *m, int c)
{
    if (c < 0 || c >= m->num_cameras)
        return sh_error_set(SH_EINVAL, "camera %d: the sequence has %d", c, m->num_cameras);
    return SH_OK;
}

static double frame_time(const phantom_model *m, int frame)
{
    return frame / m->fps;
}

static int proj_uv(const phantom_model *m, int c, double t, double u, double v, double *x, double *y)
{
    double X[3];
    phantom_surface(m, u, v, t, X);
    return phantom_project(&m->cam[c], X, x, y);
}

sh_status phantom_truth_project_at(const phantom_truth *truth, int c, double t, double u, double v,
                                   double *x, double *y)
{
    sh_status st = check_cam(&truth->model, c);
    if (st != SH_OK) return st;
    if (!proj_uv(&truth->model, c, t, u, v, x, y))
        return sh_error_set(SH_ERANGE, "surface point (%g, %g) is behind camera %d", u, v, c);
    return SH_OK;
}

sh_status phantom_truth_project(const phantom_truth *truth, int c, int frame, double u, double v,
                                double *x, double *y)
{
    return phantom_truth_project_at(truth, c, frame_time(&truth->model, frame), u, v, x, y);
}

sh_status phantom_truth_locate(const phantom_truth *truth, int c, int frame, double x, double y,
                               double *u, double *v)
{
    const phantom_model *m = &truth->model;
    sh_status st = check_cam(m, c);
    if (st != SH_OK) return st;
    double t = frame_time(m, frame);
    /* start where the undistorted ray meets the plane at mid dome height: (u, v) ~ (X, Y) */
    const phantom_camera *cam = &m->cam[c];
    double xn, yn, C[3];
    phantom_undistort(cam, x, y, &xn, &yn);
    phantom_camera_center(cam, C);
    double d[3];
    for (int i = 0; i < 3; i++) d[i] = cam->R[i] * xn + cam->R[3 + i] * yn + cam->R[6 + i];
    double s = fabs(d[2]) > 1e-12 ? (0.5 * m->dome_height - C[2]) / d[2] : 0.0;
    double a = C[0] + s * d[0], b = C[1] + s * d[1];
    /* a camera motion has slid the patch under the ray: slide the start back */
    double mv[3];
    phantom_camera_motion(m, t, mv);
    a -= mv[0];
    b -= mv[1];
    /* Newton with a finite-difference Jacobian (the map is smooth; h is far below a pixel) and
     * step halving, so that a start outside the patch cannot run away */
    const double h = 1e-4;
    double px, py;
    if (!proj_uv(m, c, t, a, b, &px, &py)) return sh_error_set(SH_ERANGE, "pixel (%g, %g): no surface", x, y);
    double err = hypot(px - x, py - y);
    int it;
    for (it = 0; it < 60 && err > 1e-10; it++) {
        double ax, ay, bx, by;
        if (!proj_uv(m, c, t, a + h, b, &ax, &ay) || !proj_uv(m, c, t, a, b + h, &bx, &by)) break;
        double j11 = (ax - px) / h, j21 = (ay - py) / h, j12 = (bx - px) / h, j22 = (by - py) / h;
        double det = j11 * j22 - j12 * j21;
        if (!(fabs(det) > 1e-300)) break;
        double rx = x - px, ry = y - py;
        double da = (j22 * rx - j12 * ry) / det, db = (-j21 * rx + j11 * ry) / det;
        double lam = 1.0;
        for (int k = 0; k < 30; k++, lam *= 0.5) {
            double qx, qy;
            if (proj_uv(m, c, t, a + lam * da, b + lam * db, &qx, &qy)) {
                double e2 = hypot(qx - x, qy - y);
                if (e2 < err || k == 29) {
                    a += lam * da;
                    b += lam * db;
                    px = qx;
                    py = qy;
                    err = e2;
                    break;
                }
            }
        }
    }
    *u = a;
    *v = b;
    if (!(err < 1e-6))
        return sh_error_set(SH_ERANGE, "camera %d frame %d pixel (%g, %g): no surface point found "
                            "(residual %g px)", c, frame, x, y, err);
    if (!phantom_on_patch(m, a, b))
        return sh_error_set(SH_ERANGE, "camera %d frame %d pixel (%g, %g) does not see the patch",
                            c, frame, x, y);
    return SH_OK;
}

/* Sticker i's point (a, b) hit by the ray of normalised coordinates (xn, yn), if any. */
static int hit_sticker(const phantom_model *m, int c, double t, int i, double xn, double yn,
                       double *a, double *b)
{
    const phantom_camera *cam = &m->cam[c];
    double C[3], d[3], O[3], ea[3], eb[3];
    phantom_camera_center(cam, C);
    for (int k = 0; k < 3; k++) d[k] = cam->R[k] * xn + cam->R[3 + k] * yn + cam->R[6 + k];
    phantom_tag_frame(m, i, t, O, ea, eb);
    /* a ea + b eb - s d = C - O, by Cramer's rule */
    double r[3] = {C[0] - O[0], C[1] - O[1], C[2] - O[2]};
    double nd[3] = {-d[0], -d[1], -d[2]};
#define DET3(p, q, w) (p[0] * (q[1] * w[2] - q[2] * w[1]) - q[0] * (p[1] * w[2] - p[2] * w[1]) + \
                       w[0] * (p[1] * q[2] - p[2] * q[1]))
    double det = DET3(ea, eb, nd);
    if (!(fabs(det) > 1e-12)) return 0;
    *a = DET3(r, eb, nd) / det;
    *b = DET3(ea, r, nd) / det;
    double s = DET3(ea, eb, r) / det;
#undef DET3
    double half = 0.5 * phantom_sticker_size(m);
    return s > 0 && fabs(*a) <= half && fabs(*b) <= half;
}

sh_status phantom_truth_locate_content(const phantom_truth *truth, int c, int frame, double x,
                                       double y, phantom_content *p)
{
    const phantom_model *m = &truth->model;
    p->marker = -1;
    sh_status st = phantom_truth_locate(truth, c, frame, x, y, &p->u, &p->v);
    if (st != SH_OK && st != SH_ERANGE) return st;
    /* a sticker strays from the tissue under it by < 1 mm: only markers whose sticker covers
     * the tissue point found, give or take, can be hit */
    double half = 0.5 * phantom_sticker_size(m), reach = half + 0.25 * half + 1.0;
    double xn, yn, t = frame_time(m, frame);
    phantom_undistort(&m->cam[c], x, y, &xn, &yn);
    for (int i = 0; i < m->num_markers; i++) {
        double a, b;
        if (fabs(p->u - m->marker[i].u) > reach || fabs(p->v - m->marker[i].v) > reach) continue;
        if (hit_sticker(m, c, t, i, xn, yn, &a, &b)) {
            p->marker = i;
            p->u = m->marker[i].u + a;
            p->v = m->marker[i].v + b;
            return SH_OK;
        }
    }
    return st;
}

sh_status phantom_truth_project_content(const phantom_truth *truth, int c, int frame,
                                        const phantom_content *p, double *x, double *y)
{
    const phantom_model *m = &truth->model;
    if (p->marker < 0) return phantom_truth_project(truth, c, frame, p->u, p->v, x, y);
    sh_status st = check_cam(m, c);
    if (st != SH_OK) return st;
    if (p->marker >= m->num_markers)
        return sh_error_set(SH_EINVAL, "marker %d: the sequence has %d", p->marker, m->num_markers);
    double X[3];
    phantom_sticker_point(m, p->marker, p->u - m->marker[p->marker].u, p->v - m->marker[p->marker].v,
                          frame_time(m, frame), X);
    if (!phantom_project(&m->cam[c], X, x, y))
        return sh_error_set(SH_ERANGE, "sticker point is behind camera %d", c);
    return SH_OK;
}

int phantom_truth_content_visible(const phantom_truth *truth, int c, int frame,
                                  const phantom_content *p)
{
    const phantom_model *m = &truth->model;
    if (c < 0 || c >= m->num_cameras || p->marker >= m->num_markers) return 0;
    if (p->marker < 0) return phantom_truth_visible(truth, c, frame, p->u, p->v);
    return phantom_sticker_visible(m, c, frame_time(m, frame), p->marker,
                                   p->u - m->marker[p->marker].u, p->v - m->marker[p->marker].v);
}

sh_status phantom_truth_where(const phantom_truth *truth, int c, int ref_frame, double x, double y,
                              int frame, double *x_t, double *y_t)
{
    phantom_content p;
    sh_status st = phantom_truth_locate_content(truth, c, ref_frame, x, y, &p);
    if (st != SH_OK) return st;
    return phantom_truth_project_content(truth, c, frame, &p, x_t, y_t);
}

int phantom_truth_visible(const phantom_truth *truth, int c, int frame, double u, double v)
{
    const phantom_model *m = &truth->model;
    if (c < 0 || c >= m->num_cameras) return 0;
    return phantom_visible(m, c, frame_time(m, frame), u, v);
}

int phantom_truth_num_markers(const phantom_truth *truth)
{
    return truth->model.num_markers;
}

sh_status phantom_truth_marker(const phantom_truth *truth, int c, int frame, int i, int k,
                               int *id, double *x, double *y, double X[3], int *visible)
{
    const phantom_model *m = &truth->model;
    sh_status st = check_cam(m, c);
    if (st != SH_OK) return st;
    if (i < 0 || i >= m->num_markers || k < 0 || k >= PHANTOM_POINTS)
        return sh_error_set(SH_EINVAL, "marker %d point %d: %d markers of %d points", i, k,
                            m->num_markers, PHANTOM_POINTS);
    double t = frame_time(m, frame), P[3], px = NAN, py = NAN;
    phantom_marker_point(m, i, k, t, P);
    int front = phantom_project(&m->cam[c], P, &px, &py);
    if (id) *id = m->marker[i].id;
    if (x) *x = px;
    if (y) *y = py;
    if (X) memcpy(X, P, sizeof P);
    if (visible) *visible = front && phantom_marker_visible(m, c, t, i, k);
    return SH_OK;
}

sh_status phantom_truth_decoy(const phantom_truth *truth, int c, int frame, int k, int *id,
                              double *x, double *y, int *visible)
{
    const phantom_model *m = &truth->model;
    sh_status st = check_cam(m, c);
    if (st != SH_OK) return st;
    if (!m->decoy) return sh_error_set(SH_EINVAL, "this sequence has no decoy (render with --occlusions)");
    if (k < 0 || k >= PHANTOM_POINTS) return sh_error_set(SH_EINVAL, "decoy point %d: 0..4", k);
    double P[3], px = NAN, py = NAN, t = frame_time(m, frame);
    phantom_decoy_point(m, k, t, P);
    int front = phantom_project(&m->cam[c], P, &px, &py);
    if (id) *id = m->decoy_id;
    if (x) *x = px;
    if (y) *y = py;
    if (visible) *visible = front && phantom_point_visible(m, c, t, P);
    return SH_OK;
}
