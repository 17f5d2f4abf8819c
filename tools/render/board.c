/* The calibration target: a planar checkerboard in varied poses, drawn on the CPU.
 *
 * Not through OSMesa as the heart is: a calibration test measures corner positions to a few
 * hundredths of a pixel, and GL's texture filtering and linear interpolation inside triangles
 * bend edges by more than that. Here every pixel is the exact area average of what it sees:
 * the board is a plane, so a pixel corner's undistorted ray (computed once per camera: the
 * lens does not move) maps onto the board through one homography per pose; pixels whose
 * neighbourhood is all one colour take it, the others are integrated on a 16 x 16 grid. The
 * sensor model (blur, noise, I420) is the heart's. */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "render.h"
#include "stillheart/camera.h"

#define SUB 16             /* samples per pixel side where colours meet */
#define BLACK_DN 25        /* printed black and white under the rig's light, 8-bit RGB */
#define WHITE_DN 217

sh_status rd_board_parse(const char *spec, rd_board *b)
{
    memset(b, 0, sizeof *b);
    const char *p = spec;
    if (strncmp(p, "checkerboard:", 13) != 0)
        return sh_error_set(SH_EINVAL, "--calib-target '%s': checkerboard:COLSxROWS:SQUARE_MM", spec);
    p += 13;
    char *end;
    errno = 0;
    long cols = strtol(p, &end, 10);
    if (end == p || *end != 'x' || errno) goto bad;
    p = end + 1;
    long rows = strtol(p, &end, 10);
    if (end == p || *end != ':' || errno) goto bad;
    p = end + 1;
    double sq = strtod(p, &end);
    if (end == p || *end || errno) goto bad;
    if (cols < 3 || rows < 3 || cols > 40 || rows > 40)
        return sh_error_set(SH_EINVAL, "--calib-target '%s': 3 to 40 inner corners each way", spec);
    if ((cols + rows) % 2 == 0)
        return sh_error_set(SH_EINVAL, "--calib-target '%s': one count odd and one even, so that the "
                                       "board's orientation shows (as stillheart-calib requires)", spec);
    if (!(sq >= 1 && sq <= 100))
        return sh_error_set(SH_EINVAL, "--calib-target '%s': squares of 1 to 100 mm", spec);
    b->cols = (int)cols;
    b->rows = (int)rows;
    b->square = sq;
    return SH_OK;
bad:
    return sh_error_set(SH_EINVAL, "--calib-target '%s': checkerboard:COLSxROWS:SQUARE_MM (inner corners, "
                                   "e.g. checkerboard:9x6:8)", spec);
}

void rd_board_point(const rd_board_pose *p, double u, double v, double X[3])
{
    for (int i = 0; i < 3; i++) X[i] = p->R[3 * i] * u + p->R[3 * i + 1] * v + p->t[i];
}

/* Rotation by angle about unit axis a (Rodrigues), row major. */
static void axis_angle(const double a[3], double ang, double R[9])
{
    double c = cos(ang), s = sin(ang), C = 1 - c;
    R[0] = c + a[0] * a[0] * C, R[1] = a[0] * a[1] * C - a[2] * s, R[2] = a[0] * a[2] * C + a[1] * s;
    R[3] = a[1] * a[0] * C + a[2] * s, R[4] = c + a[1] * a[1] * C, R[5] = a[1] * a[2] * C - a[0] * s;
    R[6] = a[2] * a[0] * C - a[1] * s, R[7] = a[2] * a[1] * C + a[0] * s, R[8] = c + a[2] * a[2] * C;
}

static void matmul3(const double A[9], const double B[9], double C[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}

/* The printed board, white margin included, in board mm: one square of black/white checker
 * beyond the inner corners each way, then a white margin of one square. */
static void board_extent(const rd_board *b, double *u0, double *v0, double *u1, double *v1)
{
    *u0 = -2 * b->square, *v0 = -2 * b->square;
    *u1 = (b->cols + 1) * b->square, *v1 = (b->rows + 1) * b->square;
}

/* 1 when the whole board is in view of every camera (2 % margin) and faces it. */
static int pose_ok(const phantom_model *m, const rd_board *b, const rd_board_pose *p)
{
    double u0, v0, u1, v1;
    board_extent(b, &u0, &v0, &u1, &v1);
    double mx = 0.02 * m->width, my = 0.02 * m->height;
    for (int c = 0; c < m->num_cameras; c++) {
        double C[3], n[3] = {p->R[2], p->R[5], p->R[8]}, d = 0;
        phantom_camera_center(&m->cam[c], C);
        for (int i = 0; i < 3; i++) d += n[i] * (C[i] - p->t[i]);
        if (d >= 0) return 0; /* the board's normal points away from its printed face */
        for (int k = 0; k < 4; k++) {
            double X[3], x, y;
            rd_board_point(p, k & 1 ? u1 : u0, k & 2 ? v1 : v0, X);
            if (!phantom_project(&m->cam[c], X, &x, &y)) return 0;
            if (x < mx || x > m->width - 1 - mx || y < my || y > m->height - 1 - my) return 0;
        }
    }
    return 1;
}

sh_status rd_board_poses(const phantom_model *m, const rd_board *b, int n, uint64_t seed,
                         rd_board_pose *out)
{
    /* Upright: u along world +X, v along -Y (the cameras' image down), the printed face up. */
    static const double base[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
    uint64_t rng = seed * 0x2545F4914F6CDD1Dull + 0xB0A2D;
    double cu = 0.5 * (b->cols - 1) * b->square, cv = 0.5 * (b->rows - 1) * b->square;
    for (int i = 0; i < n; i++) {
        int found = 0;
        for (int attempt = 0; attempt < 20000 && !found; attempt++) {
            /* Tilt directions spread round the circle (golden angle), 15-40 degrees, so that every
             * view adds perspective in a new direction (Zhang's method needs it); a few nearly
             * frontal views for the principal point. Shrink the range as attempts fail. */
            double shrink = 1.0 - 0.5 * attempt / 20000.0;
            double az = 2.399963229728653 * i + phantom_uniform(&rng, -0.3, 0.3);
            double tilt = (i % 5 == 4 ? phantom_uniform(&rng, 0, 8) : phantom_uniform(&rng, 25, 50)) * shrink * M_PI / 180;
            double spin = phantom_uniform(&rng, -25, 25) * M_PI / 180;
            double axis[3] = {cos(az), sin(az), 0}, nz[3] = {0, 0, 1};
            double Rt[9], Rs[9], tmp[9];
            axis_angle(axis, tilt, Rt);
            axis_angle(nz, spin, Rs);
            matmul3(Rs, base, tmp);
            matmul3(Rt, tmp, out[i].R);
            double centre[3] = {phantom_uniform(&rng, -30, 30) * shrink, phantom_uniform(&rng, -20, 20) * shrink,
                                phantom_uniform(&rng, -20, 140)};
            for (int k = 0; k < 3; k++) out[i].t[k] = centre[k] - (out[i].R[3 * k] * cu + out[i].R[3 * k + 1] * cv);
            found = pose_ok(m, b, &out[i]);
        }
        if (!found)
            return sh_error_set(SH_EINVAL, "the board (%dx%d corners of %g mm) does not fit the view of "
                                "every camera in a tilted pose: use smaller squares", b->cols, b->rows, b->square);
    }
    return SH_OK;
}

struct rd_board_raster {
    int width, height;
    float *ray; /* (width + 1) x (height + 1) pixel corners: undistorted x/z, y/z */
    uint8_t *cls;
    uint8_t *near; /* width x height: 1 near a corner of a square (see rd_board_draw) */
};

sh_status rd_board_raster_create(const phantom_model *m, int c, rd_board_raster **out)
{
    *out = NULL;
    rd_board_raster *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "board: out of memory");
    r->width = m->width;
    r->height = m->height;
    size_t n = (size_t)(m->width + 1) * (m->height + 1);
    r->ray = malloc(n * 2 * sizeof(float));
    r->cls = malloc(n);
    r->near = malloc((size_t)m->width * m->height);
    if (!r->ray || !r->cls || !r->near) {
        rd_board_raster_destroy(r);
        return sh_error_set(SH_ENOMEM, "board: out of memory for a %dx%d view", m->width, m->height);
    }
    /* libstillheart's undistortion (Newton to 1e-15): the phantom's 50 fixed-point steps per
     * corner were half the rendering time */
    const phantom_camera *pc = &m->cam[c];
    sh_calib_camera cam;
    memset(&cam, 0, sizeof cam);
    double K[9] = {pc->fx, 0, pc->cx, 0, pc->fy, pc->cy, 0, 0, 1};
    memcpy(cam.K, K, sizeof K);
    memcpy(cam.dist, pc->dist, sizeof pc->dist);
    cam.num_dist = 5;
    for (int y = 0; y <= m->height; y++)
        for (int x = 0; x <= m->width; x++) {
            double uv[2] = {x - 0.5, y - 0.5}, xn[2];
            if (sh_camera_undistort(&cam, uv, xn) != SH_OK) {
                rd_board_raster_destroy(r);
                return sh_error_set(SH_EINVAL, "board: camera %d's distortion cannot be inverted at pixel "
                                    "(%g, %g)", c, uv[0], uv[1]);
            }
            float *q = r->ray + 2 * ((size_t)y * (m->width + 1) + x);
            q[0] = (float)xn[0];
            q[1] = (float)xn[1];
        }
    *out = r;
    return SH_OK;
}

void rd_board_raster_destroy(rd_board_raster *r)
{
    if (!r) return;
    free(r->ray);
    free(r->cls);
    free(r->near);
    free(r);
}

typedef struct {
    double H[9]; /* undistorted normalised (a, b, 1) -> board (u, v, 1), up to scale */
    double u0, v0, u1, v1, sq;
} board_map;

/* 0: off the board, 1: black, 2: white. */
static inline int classify(const board_map *bm, double a, double b)
{
    const double *H = bm->H;
    double w = H[6] * a + H[7] * b + H[8];
    double u = (H[0] * a + H[1] * b + H[2]) / w, v = (H[3] * a + H[4] * b + H[5]) / w;
    if (!(u >= bm->u0 && u < bm->u1 && v >= bm->v0 && v < bm->v1)) return 0;
    double fi = floor(u / bm->sq), fj = floor(v / bm->sq);
    if (fi < -1 || fj < -1 || fi > (bm->u1 / bm->sq) - 2 || fj > (bm->v1 / bm->sq) - 2) return 2;
    return ((long)fi + (long)fj) & 1 ? 2 : 1;
}

static int invert3(const double A[9], double B[9])
{
    double c0 = A[4] * A[8] - A[5] * A[7], c1 = A[5] * A[6] - A[3] * A[8], c2 = A[3] * A[7] - A[4] * A[6];
    double det = A[0] * c0 + A[1] * c1 + A[2] * c2;
    if (fabs(det) < 1e-300) return 0;
    double id = 1 / det;
    B[0] = c0 * id, B[1] = (A[2] * A[7] - A[1] * A[8]) * id, B[2] = (A[1] * A[5] - A[2] * A[4]) * id;
    B[3] = c1 * id, B[4] = (A[0] * A[8] - A[2] * A[6]) * id, B[5] = (A[2] * A[3] - A[0] * A[5]) * id;
    B[6] = c2 * id, B[7] = (A[1] * A[6] - A[0] * A[7]) * id, B[8] = (A[0] * A[4] - A[1] * A[3]) * id;
    return 1;
}

sh_status rd_board_draw(rd_board_raster *r, const phantom_camera *cam, const rd_board *b,
                        const rd_board_pose *p, const uint8_t *drape, uint8_t *rgba)
{
    /* camera from board: columns R_c R_b e1, R_c R_b e2, R_c t_b + t_c map (u, v, 1) to a ray */
    double G[9];
    for (int i = 0; i < 3; i++) {
        const double *Rc = cam->R + 3 * i;
        G[3 * i] = Rc[0] * p->R[0] + Rc[1] * p->R[3] + Rc[2] * p->R[6];
        G[3 * i + 1] = Rc[0] * p->R[1] + Rc[1] * p->R[4] + Rc[2] * p->R[7];
        G[3 * i + 2] = Rc[0] * p->t[0] + Rc[1] * p->t[1] + Rc[2] * p->t[2] + cam->t[i];
    }
    board_map bm;
    if (!invert3(G, bm.H)) return sh_error_set(SH_EDEGENERATE, "board: seen edge-on");
    board_extent(b, &bm.u0, &bm.v0, &bm.u1, &bm.v1);
    bm.sq = b->square;
    int W = r->width, Hh = r->height, W1 = W + 1;
    for (size_t k = 0; k < (size_t)W1 * (Hh + 1); k++) r->cls[k] = (uint8_t)classify(&bm, r->ray[2 * k], r->ray[2 * k + 1]);
    /* An edge crossing a pixel changes the colour of some of its corners, unless a square's
     * corner pokes into the pixel: the pixels around every corner of the lattice (the board's
     * outline included) are integrated whatever their corners say. */
    memset(r->near, 0, (size_t)W * Hh);
    for (int j = -2; j <= b->rows + 1; j++)
        for (int i = -2; i <= b->cols + 1; i++) {
            double X[3], px, py;
            rd_board_point(p, i * b->square, j * b->square, X);
            if (!phantom_project(cam, X, &px, &py) || !(px > -3 && px < W + 2 && py > -3 && py < Hh + 2)) continue;
            for (int y = (int)floor(py) - 1; y <= (int)floor(py) + 2; y++)
                for (int x = (int)floor(px) - 1; x <= (int)floor(px) + 2; x++)
                    if (x >= 0 && x < W && y >= 0 && y < Hh) r->near[(size_t)y * W + x] = 1;
        }
    for (int y = 0; y < Hh; y++)
        for (int x = 0; x < W; x++) {
            const uint8_t *c0 = r->cls + (size_t)y * W1 + x, *c1 = c0 + W1;
            int first = c0[0];
            int mixed = r->near[(size_t)y * W + x] || c0[1] != first || c1[0] != first || c1[1] != first;
            int count[3] = {0, 0, 0};
            if (!mixed) {
                count[first] = SUB * SUB;
            } else {
                const float *q00 = r->ray + 2 * ((size_t)y * W1 + x), *q10 = q00 + 2, *q01 = q00 + 2 * W1,
                            *q11 = q01 + 2;
                for (int j = 0; j < SUB; j++)
                    for (int i = 0; i < SUB; i++) {
                        double s = (i + 0.5) / SUB, t = (j + 0.5) / SUB;
                        double a = (1 - t) * ((1 - s) * q00[0] + s * q10[0]) + t * ((1 - s) * q01[0] + s * q11[0]);
                        double bb = (1 - t) * ((1 - s) * q00[1] + s * q10[1]) + t * ((1 - s) * q01[1] + s * q11[1]);
                        count[classify(&bm, a, bb)]++;
                    }
            }
            const uint8_t *bg = drape + 3 * ((size_t)y * W + x);
            uint8_t *o = rgba + 4 * ((size_t)y * W + x);
            int board = count[1] * BLACK_DN + count[2] * WHITE_DN;
            for (int k = 0; k < 3; k++)
                o[k] = (uint8_t)((board + count[0] * bg[k] + SUB * SUB / 2) / (SUB * SUB));
            o[3] = 255;
        }
    return SH_OK;
}
