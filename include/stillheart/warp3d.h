/* 3D stabilization (paper section IV, Algorithm 2), split like the 2D warp (docs/architecture.md,
 * "Once per reference, once per frame"):
 *
 *  - sh_warp3d_model: one reference marker set. A surface frame (origin at the markers'
 *    centroid, axes from their PCA: X', Y' in the fitted plane, Z' along its normal) in which
 *    the reference surface is a function Z' = s(X', Y'): a least-squares quadric trend plus any
 *    2D interpolant of the residual (multilevel B-splines by default), so s interpolates the
 *    markers and reproduces quadrics exactly. The displacement h(X', Y') from reference to
 *    current 3D positions: a least-squares trend in (1, X', Y', s(X', Y')) -- that is, a 3D
 *    affine map of the surface, which holds every rigid motion exactly -- plus the 2D
 *    interpolant of the residual, one interpolant applied to the three components. h is
 *    linear in the current positions (paper IV-B allows h over (X', Y')).
 *    sh_warp3d_model_update takes the current positions: a small least-squares product and one
 *    fit of the interpolant (no allocation).
 *
 *  - sh_warp3d_view: one output camera (the reference view, a virtual stereo eye, any pose)
 *    seeing the reference surface (optionally exaggerated along its normal), and the source
 *    camera whose frames give the colour. Per reference: a grid over the output image's hull
 *    (the convex hull of the reference markers as that camera sees them); at every grid node
 *    the ray through the node (lens distortion honoured) is intersected with the surface,
 *    which fixes the node's surface parameter (X', Y'), its reference point and the interpolant's
 *    basis there. Per frame: node point = reference point + h, projected into the source camera
 *    with its distortion; the grid is refined (spacing halved) while the same bilinear error
 *    bound as the 2D engine's exceeds max_error. The view's map is an sh_warp_model of the 2D
 *    engine, so sh_warp_apply renders it (threads, bilinear sampling, black outside the hull
 *    and the frame) and sh_warp_model_map exports it.
 *
 * Units: world millimetres as in the calibration file (X_cam = R X + t); pixels with the
 * centre of the top-left pixel at (0, 0), as in OpenCV. */
#ifndef STILLHEART_WARP3D_H
#define STILLHEART_WARP3D_H

#include <stdio.h>

#include "stillheart/calib.h"
#include "stillheart/hull.h"
#include "stillheart/image.h"
#include "stillheart/interp.h"
#include "stillheart/warp.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    sh_interp_params surface;      /* residual of s over (X', Y') in mm; default bspline */
    sh_interp_params displacement; /* residual of h over (X', Y') in mm; default bspline */
    int surface_trend;             /* polynomial degree of the trend: 3 (default; needs >= 12
                                      markers, else the highest degree they allow), 2, 1 */
} sh_warp3d_params;

void sh_warp3d_params_default(sh_warp3d_params *params);

typedef struct sh_warp3d_model sh_warp3d_model;

/* ref_xyz: n reference marker positions (world mm, X0,Y0,Z0,X1,...); copied. Needs n >= 4 and
 * markers that span a plane; the surface must be a function over that plane. */
sh_status sh_warp3d_model_create(const sh_warp3d_params *params, const double *ref_xyz, int n,
                                 sh_warp3d_model **out);
void sh_warp3d_model_destroy(sh_warp3d_model *model);
int sh_warp3d_model_num_points(const sh_warp3d_model *model);

/* The same with a smoothing of each point's own (point_smoothing: n values >= 0, in the kernel's
 * units over (X', Y') in mm; NULL: none), given to the surface's and the displacement's
 * interpolants where they take one (sh_interp_create_smoothed: the RBFs): a natural landmark, less
 * certain than a marker, is approximated by both, the markers (0) still met. A TPS smoothing given
 * in pixels, lambda_px, is the same fit over mm as lambda_px / s^2 where the camera sees s px a mm
 * (sh_warp3d_pixels_per_mm): the kernel's log term of the scale falls into the affine part's
 * constant under TPS's side conditions. A B-spline with automatic levels takes as many as the
 * points without a smoothing (the markers) need, so that landmarks closer together than that
 * lattice resolves are approximated (with the markers near them) instead of refining it past its
 * size limit; affine and pwlinear interpolate every point. */
sh_status sh_warp3d_model_create_smoothed(const sh_warp3d_params *params, const double *ref_xyz, int n,
                                          const double *point_smoothing, sh_warp3d_model **out);
/* How many pixels of cam a millimetre of the points' surface spans (n >= 3 world points, those in
 * front of cam): the fourth root of the ratio of the areas they span in the image and in their
 * own plane (covariance determinants), f / Z for a plane facing the camera at depth Z, and the
 * geometric mean of the two scales of one it foreshortens. SH_EDEGENERATE for points on a line
 * or fewer than 3 in front. */
sh_status sh_warp3d_pixels_per_mm(const sh_calib_camera *cam, const double *xyz, int n, double *out);

/* The current positions of the same n markers, in the same order. Allocation-free. */
sh_status sh_warp3d_model_update(sh_warp3d_model *model, const double *cur_xyz);
/* The displacement through the points with use[k] != 0 alone (natural landmarks that come and
 * go every frame, landmarks.h): its trend by least squares over them, its interpolant by
 * sh_interp_fit_subset (affine and the RBFs: the interpolant through them alone; bspline on the
 * model's lattices; pwlinear refuses). The surface stays the one through every reference point.
 * A left-out point's cur_xyz is not read. use NULL: sh_warp3d_model_update. The first call
 * allocates the subset fit's work (kept with the model), later ones nothing. SH_EDEGENERATE for
 * fewer used points than the trend has terms, or ones that do not determine it. */
sh_status sh_warp3d_model_update_subset(sh_warp3d_model *model, const double *cur_xyz, const unsigned char *use);

/* The surface frame: origin and rows e1, e2, normal (world). A world point is
 * origin + X' e1 + Y' e2 + Z' normal. */
void sh_warp3d_model_frame(const sh_warp3d_model *model, double origin[3], double axes[9]);
/* The markers' convex hull in (X', Y'), mm: where the surface is defined for export. */
const sh_hull *sh_warp3d_model_uv_hull(const sh_warp3d_model *model);
/* s(X', Y') in mm. */
double sh_warp3d_model_height(const sh_warp3d_model *model, double u, double v);
/* World point of the surface at (X', Y') = (u, v): the reference surface with its height scaled
 * by depth_scale (current = 0), or where that point is in the last update (current = 1:
 * reference point + h(u, v); depth_scale applies to the reference point only). */
void sh_warp3d_model_point(const sh_warp3d_model *model, double u, double v, double depth_scale,
                           int current, double X[3]);

/* Surface parameter (X', Y') where the ray through pixel (x, y) of cam first meets the
 * reference surface with its height scaled by depth_scale: what sh_warp3d_view_locate answers
 * for a view seen from cam, without building one. SH_ERANGE on a miss. */
sh_status sh_warp3d_model_locate(const sh_warp3d_model *model, const sh_calib_camera *cam, double depth_scale,
                                 double x, double y, double uv[2]);

/* ---- cameras (OpenCV's pinhole + distortion model, as the calibration file holds it) ---- */

/* Pixel of a world point, distortion applied. Returns 0 when the point is not in front. */
int sh_warp3d_project(const sh_calib_camera *cam, const double X[3], double *x, double *y);
/* The ray through pixel (x, y): camera centre C and unit direction d (world). Inverts the
 * distortion by Newton's method. Returns 0 when that does not converge. */
int sh_warp3d_ray(const sh_calib_camera *cam, double x, double y, double C[3], double d[3]);
/* A parallel stereo rig around cam: the same intrinsics without distortion and the same
 * orientation, centres moved by -/+ baseline/2 along the camera's x axis (left, right).
 * The disparity x_left - x_right of a point at depth Z is f_x * baseline / Z. */
void sh_warp3d_stereo_cameras(const sh_calib_camera *cam, double baseline,
                              sh_calib_camera *left, sh_calib_camera *right);
/* A virtual camera: cam's intrinsics without distortion, the scene turned about `centre`
 * (world) by the rotation vector rvec (radians, in cam's axes) and then shifted by tvec (mm,
 * in cam's axes): X_virtual = Rd (X_cam - c) + c + tvec, with c = centre in cam's axes. */
void sh_warp3d_pose_camera(const sh_calib_camera *cam, const double centre[3],
                           const double rvec[3], const double tvec[3], sh_calib_camera *out);

/* ---- views ---- */

typedef struct {
    sh_warp_options warp;  /* max_error (px) and initial grid spacing, as the 2D engine */
    double depth_scale;    /* height above the fitted plane is multiplied by this (default 1) */
} sh_warp3d_view_options;

void sh_warp3d_view_options_default(sh_warp3d_view_options *opts);

typedef struct sh_warp3d_view sh_warp3d_view;

/* view_cam: the output camera; source_cam: the camera the frames come from. Both images are
 * width x height. The model must outlive the view. */
sh_status sh_warp3d_view_create(const sh_warp3d_model *model, const sh_calib_camera *view_cam,
                                const sh_calib_camera *source_cam, int width, int height,
                                const sh_warp3d_view_options *opts, sh_warp3d_view **out);
void sh_warp3d_view_destroy(sh_warp3d_view *view);

/* The map for the model's last update (allocates only when the grid must be refined). With
 * opts.warp.defer_refine the grid is kept whatever its bound: sh_warp_model_finer_spacing of the
 * view's map model says which spacing is due, for a caller with a deadline to build that grid on
 * another thread (sh_warp3d_view_grid_build) and swap it in between updates. */
sh_status sh_warp3d_view_update(sh_warp3d_view *view);

typedef struct sh_warp3d_grid sh_warp3d_grid;
/* A grid for view at spacing h (a power of two), apart from the view. It reads only what the
 * view's creation and the model's reference fixed, so it may run while another thread updates
 * the model and the view; the model must outlive it. */
sh_status sh_warp3d_view_grid_build(const sh_warp3d_view *view, int h, sh_warp3d_grid **out);
/* Puts grid in view's place, projected with the model's last update, and the view's old grid in
 * grid (to destroy). Same thread as the updates. */
void sh_warp3d_view_grid_swap(sh_warp3d_view *view, sh_warp3d_grid *grid);
void sh_warp3d_grid_destroy(sh_warp3d_grid *grid);

/* The 2D warp model holding the view's map: give it to sh_warp_apply / sh_warp_model_map. */
const sh_warp_model *sh_warp3d_view_map_model(const sh_warp3d_view *view);
const sh_hull *sh_warp3d_view_hull(const sh_warp3d_view *view);
int sh_warp3d_view_grid_spacing(const sh_warp3d_view *view);
double sh_warp3d_view_error_bound(const sh_warp3d_view *view);
/* Surface parameter (X', Y') hit by the ray through output pixel (x, y). SH_ERANGE on a miss. */
sh_status sh_warp3d_view_locate(const sh_warp3d_view *view, double x, double y, double uv[2]);

/* Renders into a width x height window of out at (ox, oy) (even offsets for I420): stereo
 * layouts put two views side by side or one above the other. */
sh_status sh_warp3d_view_apply(sh_warp *warp, const sh_warp3d_view *view, const sh_image *current,
                               sh_image *out, int ox, int oy);

/* The squeezed stereo layouts (half-resolution side by side / top and bottom): halves full
 * along x (axis 0) or y (axis 1), averaging pixel pairs, into the window of out at (ox, oy).
 * Same format; the halved size must be even (a multiple of 4 for I420, whose chroma is halved
 * too) and the window's offsets even for I420. */
sh_status sh_warp3d_squeeze(const sh_image *full, int axis, sh_image *out, int ox, int oy);

/* The stereo pair's frame (paper section IV: the two eyes of a 3D monitor), one of four layouts:
 * side by side (2W x H), top and bottom (W x 2H), and the same squeezed into one W x H frame
 * (each eye halved along x or y: what 3D televisions take). Eye 0 (left) comes first: left or
 * top. `stillheart warp3d --layout` and the daemon's [method] layout name them alike. */
typedef enum {
    SH_WARP3D_SBS = 0,
    SH_WARP3D_TB,
    SH_WARP3D_SBS_HALF,
    SH_WARP3D_TB_HALF,
    SH_WARP3D_LAYOUT_COUNT
} sh_warp3d_layout;

/* "sbs", "tb", "sbs-half", "tb-half"; SH_EINVAL with the choices otherwise. */
sh_status sh_warp3d_layout_parse(const char *name, sh_warp3d_layout *out);
const char *sh_warp3d_layout_name(sh_warp3d_layout layout);
/* 1 for the squeezed layouts, whose eyes are rendered at full size elsewhere and placed. */
int sh_warp3d_layout_half(sh_warp3d_layout layout);
/* The frame holding two width x height eyes of format. SH_EINVAL naming the rule when it cannot
 * be made: a squeezed side not a multiple of 2 (4 for I420), or a side over SH_IMAGE_MAX_SIZE. */
sh_status sh_warp3d_layout_size(sh_warp3d_layout layout, sh_pixfmt format, int width, int height, int *frame_width,
                                int *frame_height);
/* Full-size layouts only: the view (sh_image_window) of frame where eye's width x height
 * picture goes, to render into directly. */
sh_status sh_warp3d_layout_window(sh_warp3d_layout layout, int eye, const sh_image *frame, int width, int height,
                                  sh_image *view);
/* Puts eye's full-size picture eye_img in its place in frame: copied, or squeezed
 * (sh_warp3d_squeeze) in the half layouts. */
sh_status sh_warp3d_layout_place(sh_warp3d_layout layout, int eye, const sh_image *eye_img, sh_image *frame);
/* Renders the two eyes' views (views[0] left, views[1] right, each of current's size) of current
 * into frame in layout. outside (may be NULL, or either entry): the eye's pixels outside its
 * hull filled by sh_warp_outside_apply (made for current's format and size) instead of left
 * black. eye: a current-sized scratch image, needed by the squeezed layouts only (may be NULL
 * otherwise). Allocation-free. */
sh_status sh_warp3d_stereo_apply(sh_warp *warp, const sh_warp3d_view *const views[2], sh_warp_outside *const outside[2],
                                 sh_warp3d_layout layout, const sh_image *current, sh_image *eye, sh_image *frame);

/* ---- PLY export of the surface ---- */

typedef struct sh_warp3d_ply sh_warp3d_ply;

/* Samples the surface on a square lattice of `spacing` mm in (X', Y') inside the markers' hull
 * (mesh = 1 adds the lattice's triangles). Allocates everything export needs. */
sh_status sh_warp3d_ply_create(const sh_warp3d_model *model, double spacing, int mesh,
                               sh_warp3d_ply **out);
void sh_warp3d_ply_destroy(sh_warp3d_ply *ply);
int sh_warp3d_ply_num_points(const sh_warp3d_ply *ply);
/* Writes the surface of the model's last update (current = 1) or the reference surface
 * (current = 0) as binary little-endian PLY: float x, y, z (world mm), uchar red, green, blue
 * sampled bilinearly from rgb (RGB24, may be NULL: grey) as cam sees the point. */
sh_status sh_warp3d_ply_write(sh_warp3d_ply *ply, const sh_warp3d_model *model, int current,
                              const sh_image *rgb, const sh_calib_camera *cam, const char *path);

/* The same surface as a textured mesh: base.obj (vertices, texture coordinates = each vertex's
 * pixel in cam over the frame's size, the lattice's triangles), base.mtl and base.png (rgb,
 * RGB24, the texture). Needs an exporter created with mesh = 1. */
sh_status sh_warp3d_obj_write(sh_warp3d_ply *ply, const sh_warp3d_model *model, int current,
                              const sh_image *rgb, const sh_calib_camera *cam, const char *base);

#ifdef __cplusplus
}
#endif
#endif
