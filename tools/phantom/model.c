/* The analytic heart surface X(u, v, t) and what hides it.
 *
 * The deformation is built from pieces that an affine map cannot follow: a contraction whose
 * rotation grows with the radius (twist), a contraction wave travelling along u (delay), a
 * Gaussian out-of-plane bulge and a Gaussian in-plane push with its own phase. Respiration moves
 * the whole patch rigidly, and stabilizer pads scale the motion down near them. A moved endoscope
 * translates everything seen (tissue, pads, shaft, decoy) alike, and a sudden first beat warps
 * the heart's clock. Everything is a closed form in (u, v, t), so the truth is exact and cheap to
 * evaluate anywhere. */
#include <math.h>
#include <string.h>

#include "phantom.h"

#define PI 3.14159265358979323846
#define TWO_PI 6.28318530717958647692

/* Cardiac activation: a fast rise and slower fall, like a pressure curve. */
static double activation(double hz, double phase, double t)
{
    double phi = TWO_PI * hz * t + phase;
    return 0.5 * (1.0 - cos(phi)) + 0.12 * sin(2.0 * phi);
}

void phantom_camera_motion(const phantom_model *m, double t, double d[3])
{
    double s = 0.0;
    if (m->cam_motion == PHANTOM_CAM_PAN && m->cam_motion_dur > 0) {
        double e = (t - m->cam_motion_t0) / m->cam_motion_dur;
        s = e <= 0 ? 0.0 : e >= 1 ? 1.0 : 0.5 * (1.0 - cos(PI * e));
    } else if (m->cam_motion != PHANTOM_CAM_NONE) {
        /* a bump, or a pan of no length: a step. t0 is a frame's time computed as frame / fps,
         * the same expression every caller uses, so the comparison puts the step exactly
         * between two frames. */
        s = t >= m->cam_motion_t0 ? 1.0 : 0.0;
    }
    for (int i = 0; i < 3; i++) d[i] = s * m->cam_motion_shift[i];
}

/* X += d(t). Skipped without a motion: adding a zero would turn -0.0 into 0.0 and change the
 * text of markers.csv for sequences rendered before the motion existed. */
static void add_camera_motion(const phantom_model *m, double t, double X[3])
{
    if (m->cam_motion == PHANTOM_CAM_NONE) return;
    double d[3];
    phantom_camera_motion(m, t, d);
    for (int i = 0; i < 3; i++) X[i] += d[i];
}

double phantom_heart_time(const phantom_model *m, double tl)
{
    if (!m->first_beat) return tl;
    /* Resting at phase 0 (c = 0, where a contraction starts) rather than at the curve's true
     * minimum (-0.04, just before it) makes the rest a state the normal beat passes through, so
     * that after the first beat the motion is the normal one, shifted in time. */
    double k = PHANTOM_FIRST_BEAT_SPEEDUP;
    double rest = -m->heart_phase / (TWO_PI * m->heart_hz); /* a time of phase 0 */
    double fast = 0.5 / (k * m->heart_hz);                  /* phase 0 -> pi at k times the rate */
    double e = tl - m->first_beat_at;
    if (e <= 0) return rest;
    if (e < fast) return rest + k * e;
    return rest + e + (k - 1.0) * fast; /* continuous at e = fast: rest + k fast */
}

static double seg_dist2(double pu, double pv, const phantom_pad *p)
{
    double du = p->u1 - p->u0, dv = p->v1 - p->v0;
    double len2 = du * du + dv * dv;
    double s = len2 > 0 ? ((pu - p->u0) * du + (pv - p->v0) * dv) / len2 : 0.0;
    if (s < 0) s = 0;
    if (s > 1) s = 1;
    double eu = pu - (p->u0 + s * du), ev = pv - (p->v0 + s * dv);
    return eu * eu + ev * ev;
}

static double rest_height(const phantom_model *m, double u, double v)
{
    double a = (u - m->dome_u) / m->dome_su, b = (v - m->dome_v) / m->dome_sv;
    return m->dome_height * exp(-(a * a + b * b));
}

void phantom_surface(const phantom_model *m, double u, double v, double t, double X[3])
{
    double z0 = rest_height(m, u, v);
    /* the first beat warps the lagged time, so the contraction wave runs through it too */
    double tl = phantom_heart_time(m, t - m->delay * (u + 0.5 * m->size_u) / m->size_u);
    double c = activation(m->heart_hz, m->heart_phase, tl);

    /* twist + contraction about the dome centre */
    double du = u - m->dome_u, dv = v - m->dome_v;
    double r = sqrt(du * du + dv * dv);
    double th = m->twist * c * r / m->twist_radius;
    double sc = 1.0 - m->contraction * c;
    double ct = cos(th), st = sin(th);
    double pu = m->dome_u + sc * (ct * du - st * dv);
    double pv = m->dome_v + sc * (st * du + ct * dv);

    /* local in-plane push, out of phase with the main beat */
    double qu = u - m->push_u, qv = v - m->push_v;
    double g2 = exp(-(qu * qu + qv * qv) / (m->push_sigma * m->push_sigma));
    double c2 = activation(m->heart_hz, m->heart_phase + m->push_phase, tl);
    pu += m->push * c2 * g2 * qu / m->push_sigma;
    pv += m->push * c2 * g2 * qv / m->push_sigma;

    /* out-of-plane bulge */
    double lu = u - m->lift_u, lv = v - m->lift_v;
    double g1 = exp(-(lu * lu + lv * lv) / (m->lift_sigma * m->lift_sigma));
    double pz = z0 + m->lift * c * g1;

    /* respiration: tilt about the X axis through the origin, then shift */
    if (m->resp_hz > 0) {
        double rr = 0.5 * (1.0 - cos(TWO_PI * m->resp_hz * t));
        double a = m->resp_tilt * rr, ca = cos(a), sa = sin(a);
        double y2 = ca * pv - sa * pz, z2 = sa * pv + ca * pz;
        pv = y2;
        pz = z2;
        pu += rr * m->resp_shift[0];
        pv += rr * m->resp_shift[1];
        pz += rr * m->resp_shift[2];
    }

    /* stabilizer pads hold the tissue near them at rest */
    double hold = 1.0;
    for (int i = 0; i < m->num_pads; i++)
        hold *= 1.0 - exp(-seg_dist2(u, v, &m->pad[i]) / (m->pad_falloff * m->pad_falloff));
    X[0] = u + hold * (pu - u);
    X[1] = v + hold * (pv - v);
    X[2] = z0 + hold * (pz - z0);
    add_camera_motion(m, t, X);
}


void phantom_surface_normal(const phantom_model *m, double u, double v, double t, double n[3])
{
    /* Central differences: the normal only shades pixels and tests facing, 1e-6 is plenty. */
    const double h = 1e-3;
    double a[3], b[3], c[3], d[3];
    phantom_surface(m, u + h, v, t, a);
    phantom_surface(m, u - h, v, t, b);
    phantom_surface(m, u, v + h, t, c);
    phantom_surface(m, u, v - h, t, d);
    double eu[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    double ev[3] = {c[0] - d[0], c[1] - d[1], c[2] - d[2]};
    n[0] = eu[1] * ev[2] - eu[2] * ev[1];
    n[1] = eu[2] * ev[0] - eu[0] * ev[2];
    n[2] = eu[0] * ev[1] - eu[1] * ev[0];
    double l = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (l > 0) {
        n[0] /= l;
        n[1] /= l;
        n[2] /= l;
    }
}

int phantom_on_patch(const phantom_model *m, double u, double v)
{
    return fabs(u) <= 0.5 * m->size_u && fabs(v) <= 0.5 * m->size_v;
}

void phantom_marker_uv(const phantom_model *m, int i, int k, double *u, double *v)
{
    static const double su[4] = {-0.5, 0.5, 0.5, -0.5}, sv[4] = {-0.5, -0.5, 0.5, 0.5};
    *u = m->marker[i].u;
    *v = m->marker[i].v;
    if (k >= 0 && k < 4) {
        *u += su[k] * m->tag_size;
        *v += sv[k] * m->tag_size;
    }
}

/* The tangent vectors dX/du, dX/dv at (u, v, t), by central differences. */
static void tangents(const phantom_model *m, double u, double v, double t, double ju[3], double jv[3])
{
    const double h = 1e-3;
    double a[3], b[3], c[3], d[3];
    phantom_surface(m, u + h, v, t, a);
    phantom_surface(m, u - h, v, t, b);
    phantom_surface(m, u, v + h, t, c);
    phantom_surface(m, u, v - h, t, d);
    for (int i = 0; i < 3; i++) {
        ju[i] = (a[i] - b[i]) / (2 * h);
        jv[i] = (c[i] - d[i]) / (2 * h);
    }
}

void phantom_tag_frame(const phantom_model *m, int i, double t, double O[3], double ea[3], double eb[3])
{
    phantom_surface(m, m->marker[i].u, m->marker[i].v, t, O);
    tangents(m, m->marker[i].u, m->marker[i].v, t, ea, eb);
}

void phantom_sticker_point(const phantom_model *m, int i, double a, double b, double t, double X[3])
{
    double O[3], ea[3], eb[3];
    phantom_tag_frame(m, i, t, O, ea, eb);
    for (int j = 0; j < 3; j++) X[j] = O[j] + a * ea[j] + b * eb[j];
}

void phantom_marker_point(const phantom_model *m, int i, int k, double t, double X[3])
{
    static const double su[4] = {-0.5, 0.5, 0.5, -0.5}, sv[4] = {-0.5, -0.5, 0.5, 0.5};
    double a = k < 4 ? su[k] * m->tag_size : 0, b = k < 4 ? sv[k] * m->tag_size : 0;
    phantom_sticker_point(m, i, a, b, t, X);
}

void phantom_shaft_axis(const phantom_model *m, double t, double tip[3], double end[3])
{
    double s = 0.5 * (1.0 - cos(TWO_PI * t / m->shaft_period));
    double l = sqrt(m->shaft_dir[0] * m->shaft_dir[0] + m->shaft_dir[1] * m->shaft_dir[1] +
                    m->shaft_dir[2] * m->shaft_dir[2]);
    for (int i = 0; i < 3; i++) {
        tip[i] = m->shaft_p0[i] + s * (m->shaft_p1[i] - m->shaft_p0[i]);
        end[i] = tip[i] + m->shaft_length * m->shaft_dir[i] / l;
    }
    add_camera_motion(m, t, tip);
    add_camera_motion(m, t, end);
}

double phantom_blob_radius(const phantom_model *m, int b, double t)
{
    /* grows and shrinks over 0.4 s (or --blood-spread) so the blob has a history, not a switch */
    const double ramp = m->blood_spread > 0 ? m->blood_spread : PHANTOM_BLOOD_SPREAD;
    const phantom_blob *bl = &m->blob[b];
    double e = fmin((t - bl->t0) / ramp, (bl->t1 - t) / ramp);
    if (e <= 0) return 0.0;
    if (e > 1) e = 1;
    return bl->radius * e;
}

void phantom_decoy_point(const phantom_model *m, int k, double t, double X[3])
{
    static const double su[5] = {-0.5, 0.5, 0.5, -0.5, 0}, sv[5] = {-0.5, -0.5, 0.5, 0.5, 0};
    double c = cos(m->decoy_yaw), s = sin(m->decoy_yaw);
    double a = su[k] * m->tag_size, b = sv[k] * m->tag_size;
    X[0] = m->decoy_center[0] + c * a - s * b;
    X[1] = m->decoy_center[1] + s * a + c * b;
    X[2] = m->decoy_center[2];
    add_camera_motion(m, t, X);
}

/* Squared distance between segments p0-p1 and q0-q1 (the classic clamped closest points). */
static double segseg_dist2(const double p0[3], const double p1[3], const double q0[3],
                           const double q1[3])
{
    double d1[3], d2[3], r[3];
    for (int i = 0; i < 3; i++) {
        d1[i] = p1[i] - p0[i];
        d2[i] = q1[i] - q0[i];
        r[i] = p0[i] - q0[i];
    }
    double a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2];
    double e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2];
    double f = d2[0] * r[0] + d2[1] * r[1] + d2[2] * r[2];
    double c = d1[0] * r[0] + d1[1] * r[1] + d1[2] * r[2];
    double b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2];
    double s, t;
    double den = a * e - b * b;
    s = den > 1e-12 * a * e ? (b * f - c * e) / den : 0.0;
    s = s < 0 ? 0 : (s > 1 ? 1 : s);
    t = (b * s + f) / e;
    if (t < 0) {
        t = 0;
        s = -c / a;
        s = s < 0 ? 0 : (s > 1 ? 1 : s);
    } else if (t > 1) {
        t = 1;
        s = (b - c) / a;
        s = s < 0 ? 0 : (s > 1 ? 1 : s);
    }
    double d = 0;
    for (int i = 0; i < 3; i++) {
        double w = p0[i] + s * d1[i] - (q0[i] + t * d2[i]);
        d += w * w;
    }
    return d;
}

/* World endpoints of pad i's axis: on the rest surface, lifted by its radius minus how deep the
 * pad presses (a third of the radius), as the renderer draws it. */
static void pad_axis(const phantom_model *m, int i, double t, double a[3], double b[3])
{
    const phantom_pad *p = &m->pad[i];
    double sink = m->pad_radius * (2.0 / 3.0);
    a[0] = p->u0;
    a[1] = p->v0;
    a[2] = rest_height(m, p->u0, p->v0) + sink;
    b[0] = p->u1;
    b[1] = p->v1;
    b[2] = rest_height(m, p->u1, p->v1) + sink;
    add_camera_motion(m, t, a);
    add_camera_motion(m, t, b);
}

void phantom_pad_axis(const phantom_model *m, int i, double t, double a[3], double b[3])
{
    pad_axis(m, i, t, a, b);
}

int phantom_point_visible(const phantom_model *m, int c, double t, const double X[3])
{
    double x, y;
    if (!phantom_project(&m->cam[c], X, &x, &y)) return 0;
    if (x < -0.5 || y < -0.5 || x >= m->width - 0.5 || y >= m->height - 0.5) return 0;
    double C[3];
    phantom_camera_center(&m->cam[c], C);
    if (m->shaft) {
        double tip[3], end[3];
        phantom_shaft_axis(m, t, tip, end);
        if (segseg_dist2(C, X, tip, end) < m->shaft_radius * m->shaft_radius) return 0;
    }
    for (int i = 0; i < m->num_pads; i++) {
        double a[3], b[3];
        pad_axis(m, i, t, a, b);
        if (segseg_dist2(C, X, a, b) < m->pad_radius * m->pad_radius) return 0;
    }
    if (m->decoy) {
        /* the card is a flat square (tag plus a white margin) at height decoy_center[2], moved
         * with the scene by a camera motion */
        double D[3] = {m->decoy_center[0], m->decoy_center[1], m->decoy_center[2]};
        add_camera_motion(m, t, D);
        double dz = X[2] - C[2];
        if (fabs(dz) > 1e-12) {
            double s = (D[2] - C[2]) / dz;
            if (s > 0 && s < 1 - 1e-9) {
                double px = C[0] + s * (X[0] - C[0]) - D[0];
                double py = C[1] + s * (X[1] - C[1]) - D[1];
                double cy = cos(m->decoy_yaw), sy = sin(m->decoy_yaw);
                double a = cy * px + sy * py, b = -sy * px + cy * py;
                double half = 0.5 * phantom_decoy_card(m);
                if (fabs(a) < half && fabs(b) < half) return 0;
            }
        }
    }
    return 1;
}

static int under_blob(const phantom_model *m, double t, double u, double v)
{
    for (int b = 0; b < m->num_blobs; b++) {
        double r = phantom_blob_radius(m, b, t);
        double du = u - m->blob[b].u, dv = v - m->blob[b].v;
        if (du * du + dv * dv < r * r) return 1;
    }
    return 0;
}

static int facing(const phantom_model *m, int c, const double X[3], const double n[3])
{
    double C[3];
    phantom_camera_center(&m->cam[c], C);
    return n[0] * (C[0] - X[0]) + n[1] * (C[1] - X[1]) + n[2] * (C[2] - X[2]) > 0;
}

int phantom_visible(const phantom_model *m, int c, double t, double u, double v)
{
    if (under_blob(m, t, u, v)) return 0;
    double X[3], n[3];
    phantom_surface(m, u, v, t, X);
    phantom_surface_normal(m, u, v, t, n);
    return facing(m, c, X, n) && phantom_point_visible(m, c, t, X);
}

int phantom_marker_visible(const phantom_model *m, int c, double t, int i, int k)
{
    double u, v;
    phantom_marker_uv(m, i, k, &u, &v);
    return phantom_sticker_visible(m, c, t, i, u - m->marker[i].u, v - m->marker[i].v);
}

int phantom_sticker_visible(const phantom_model *m, int c, double t, int i, double a, double b)
{
    double X[3], O[3], ea[3], eb[3];
    if (under_blob(m, t, m->marker[i].u + a, m->marker[i].v + b)) return 0;
    phantom_tag_frame(m, i, t, O, ea, eb);
    for (int j = 0; j < 3; j++) X[j] = O[j] + a * ea[j] + b * eb[j];
    double n[3] = {ea[1] * eb[2] - ea[2] * eb[1], ea[2] * eb[0] - ea[0] * eb[2], ea[0] * eb[1] - ea[1] * eb[0]};
    return facing(m, c, X, n) && phantom_point_visible(m, c, t, X);
}
