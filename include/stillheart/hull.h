/* The convex hull of the reference markers: where stabilization (and the paper's metric e) is
 * defined. Pixel (x, y) of a plane has its centre at (x, y); a pixel belongs to the hull when
 * its centre lies inside or on the boundary. */
#ifndef STILLHEART_HULL_H
#define STILLHEART_HULL_H

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_HULL_MAX_VERTICES 1024

typedef struct {
    int count;                              /* vertices, counter-clockwise (y down), no repeats */
    double x[SH_HULL_MAX_VERTICES], y[SH_HULL_MAX_VERTICES];
    double xmin, xmax, ymin, ymax;
} sh_hull;

/* Andrew's monotone chain over xy (n points as x0,y0,...). Fewer than 3 non-collinear points
 * gives SH_EDEGENERATE; NaN gives SH_EINVAL. Points beyond SH_HULL_MAX_VERTICES on the hull
 * are refused with SH_ERANGE. Allocates nothing up to 512 points (a frame's markers and
 * landmarks in the daemon). */
sh_status sh_hull_compute(const double *xy, int n, sh_hull *hull);

/* The hull's extent on the horizontal line at y: [*x0, *x1]. Returns 0 when the line misses. */
int sh_hull_row(const sh_hull *hull, double y, double *x0, double *x1);

/* Whether (x, y) lies inside or on the hull (within 1e-9 px). */
int sh_hull_contains(const sh_hull *hull, double x, double y);

/* The x that sh_hull_contains accepts on the line at y: [*lo, *hi] (its tolerance included), so
 * that sh_hull_contains(hull, x, y) is exactly *lo <= x && x <= *hi; 0 when it accepts none. One
 * call a row instead of one a point, where a whole plane is tested. */
int sh_hull_row_accepts(const sh_hull *hull, double y, double *lo, double *hi);

/* Integer pixel range [*first, *last] of the row of a plane whose pixel (px, py) sits at
 * (scale * px + offset_x, scale * py + offset_y) in hull coordinates, clipped to [0, width).
 * Returns 0 when the row holds no hull pixel. */
int sh_hull_plane_row(const sh_hull *hull, int py, int width, double scale, double offset_x,
                      double offset_y, int *first, int *last);

#ifdef __cplusplus
}
#endif
#endif
