/* The Kalman filter of one marker coordinate: baseline + rotating harmonic pairs. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "track_internal.h"

/* measurement row: p + the cosine component of every active pair */
double trk_hx(const sh_tracker *t, const axis_filter *f)
{
    double z = f->x[0];
    for (int k = 0; k < t->nh; k++) z += f->x[2 + 2 * k];
    for (int k = 0; k < t->nr; k++) z += f->x[2 + 2 * HMAX + 2 * k];
    return z;
}

void trk_h_row(const sh_tracker *t, double *h)
{
    memset(h, 0, sizeof(double) * NS);
    h[0] = 1;
    for (int k = 0; k < t->nh; k++) h[2 + 2 * k] = 1;
    for (int k = 0; k < t->nr; k++) h[2 + 2 * HMAX + 2 * k] = 1;
}

/* variance of the measured coordinate: h P h^T */
double trk_hph(const sh_tracker *t, const axis_filter *f)
{
    double h[NS], s = 0;
    trk_h_row(t, h);
    for (int i = 0; i < NS; i++) {
        if (h[i] == 0) continue;
        for (int j = 0; j < NS; j++) s += h[i] * f->P[i * NS + j] * h[j];
    }
    return s;
}

void trk_transition(const sh_tracker *t, double dt, double *F)
{
    memset(F, 0, sizeof(double) * NS * NS);
    F[0] = 1;
    if (!t->locked) F[1] = dt;
    F[NS + 1] = t->locked ? 0 : 1;
    for (int k = 0; k < HMAX + RMAX; k++) {
        double f = k < HMAX ? t->fh * (k + 1) : t->fr * (k - HMAX + 1);
        double a = 2 * PI * f * dt, c = cos(a), s = sin(a);
        int i = 2 + 2 * k;
        F[i * NS + i] = c;
        F[i * NS + i + 1] = -s;
        F[(i + 1) * NS + i] = s;
        F[(i + 1) * NS + i + 1] = c;
    }
}

void trk_predict_filter(const sh_tracker *t, axis_filter *f, const double *F, double dt)
{
    double x[NS], FP[NS * NS];
    for (int i = 0; i < NS; i++) {
        double s = 0;
        for (int j = 0; j < NS; j++) s += F[i * NS + j] * f->x[j];
        x[i] = s;
    }
    memcpy(f->x, x, sizeof x);
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) {
            double s = 0;
            for (int k = 0; k < NS; k++) s += F[i * NS + k] * f->P[k * NS + j];
            FP[i * NS + j] = s;
        }
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) {
            double s = 0;
            for (int k = 0; k < NS; k++) s += FP[i * NS + k] * F[j * NS + k];
            f->P[i * NS + j] = s;
        }
    double u = t->unit > 0 ? t->unit : 1;
    if (!t->locked) {
        double q = t->o.accel * u;
        q *= q;
        f->P[0] += q * dt * dt * dt * dt / 4;
        f->P[1] += q * dt * dt * dt / 2;
        f->P[NS] += q * dt * dt * dt / 2;
        f->P[NS + 1] += q * dt * dt;
    } else {
        f->P[0] += t->o.q_base * t->o.q_base * u * u * dt;
        double qh = t->o.q_harm * t->o.q_harm * u * u * dt;
        for (int k = 0; k < t->nh; k++) {
            int i = 2 + 2 * k;
            f->P[i * NS + i] += qh;
            f->P[(i + 1) * NS + i + 1] += qh;
        }
        for (int k = 0; k < t->nr; k++) {
            int i = 2 + 2 * HMAX + 2 * k;
            f->P[i * NS + i] += qh;
            f->P[(i + 1) * NS + i + 1] += qh;
        }
    }
}

void trk_update_filter(const sh_tracker *t, axis_filter *f, double z, double r)
{
    double h[NS], ph[NS];
    trk_h_row(t, h);
    double s = r;
    for (int i = 0; i < NS; i++) {
        double a = 0;
        for (int j = 0; j < NS; j++) a += f->P[i * NS + j] * h[j];
        ph[i] = a;
        s += h[i] * a;
    }
    double y = z - trk_hx(t, f);
    for (int i = 0; i < NS; i++) f->x[i] += ph[i] / s * y;
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) f->P[i * NS + j] -= ph[i] * ph[j] / s;
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < i; j++) {
            double a = 0.5 * (f->P[i * NS + j] + f->P[j * NS + i]);
            f->P[i * NS + j] = f->P[j * NS + i] = a;
        }
}

void trk_init_filter(axis_filter *f, double z, double r, double vvar)
{
    memset(f, 0, sizeof *f);
    f->x[0] = z;
    f->P[0] = r;
    f->P[NS + 1] = vvar;
}
