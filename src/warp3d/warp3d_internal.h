/* Private to src/warp3d. */
#ifndef STILLHEART_WARP3D_INTERNAL_H
#define STILLHEART_WARP3D_INTERNAL_H

#include "stillheart/warp3d.h"

#define W3_MAX_TREND 10 /* 1, u, v, u^2, uv, v^2, u^3, u^2 v, u v^2, v^3 */
#define W3_H_TREND 4   /* 1, u, v, s(u, v) */

struct sh_warp3d_model {
    int n;
    double *ref;              /* n x 3 world */
    double origin[3], axes[9];/* rows e1, e2, normal */
    double scale;             /* length scale of the trend bases (RMS radius, mm) */
    double *uv;               /* n x 2 */
    double *height;           /* n: Z' of each marker */
    sh_hull uv_hull;

    int s_terms;              /* surface trend: 3, 6 or 10 terms */
    double s_trend[W3_MAX_TREND];
    sh_interp *s_interp;
    double *s_coef;           /* num_coefs */

    int h_terms;              /* displacement trend: 3 or 4 terms */
    double *h_pinv;           /* h_terms x n */
    double *h_basis;          /* n x h_terms, the trend basis at the markers */
    sh_interp *h_interp;
    double *h_coef;           /* num_coefs x 3 */
    double h_trend[W3_H_TREND * 3];
    double *disp, *resid;     /* n x 3 */
    void *subset_work;        /* sh_warp3d_model_update_subset's (made by its first call) */
};


/* The displacement trend's basis at (u, v): h_terms values. */
void w3_h_basis(const sh_warp3d_model *m, double u, double v, double *b);
/* Reference world point at (u, v), height scaled by depth_scale. */
void w3_surface_point(const sh_warp3d_model *m, double u, double v, double depth_scale, double X[3]);

#endif
