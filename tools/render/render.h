/* stillheart-render internals: procedural textures, the OSMesa scene, and the sensor model. */
#ifndef STILLHEART_RENDER_H
#define STILLHEART_RENDER_H

#include <stdint.h>
#include <stdio.h>

#include "../phantom/phantom.h"
#include "stillheart/core.h"

typedef struct {
    int width, height;
    uint8_t *rgb; /* width * height * 3 */
} rd_texture;

void rd_texture_free(rd_texture *t);
/* The heart's albedo over the patch: myocardium, epicardial fat, coronary vessels. Row 0 is
 * v = -size_v/2, column 0 is u = -size_u/2; texel (i, j) covers [i, i+1) x [j, j+1) scaled. */
sh_status rd_texture_tissue(const phantom_model *m, int width, int height, rd_texture *out);
/* A surgical drape, the static background of camera `camera` (width x height RGB). */
sh_status rd_texture_drape(uint64_t seed, int camera, int width, int height, rd_texture *out);
/* The tag image of `family` code `id`, each bit `scale` texels wide (grey levels of print). */
sh_status rd_texture_tag(const char *family, int id, int scale, rd_texture *out, int *total_bits,
                         int *border_bits);

typedef struct rd_scene rd_scene;

/* Creates the OSMesa context and uploads textures. */
sh_status rd_scene_create(const phantom_model *m, rd_scene **out);
void rd_scene_destroy(rd_scene *s);
/* Moves every mesh to time t (seconds); shared by all cameras of a frame. */
void rd_scene_update(rd_scene *s, double t);
/* Renders camera c into rgba (width * height * 4, row 0 = top); alpha 0 where nothing was
 * drawn (the background). */
sh_status rd_scene_draw(rd_scene *s, int c, uint8_t *rgba);

/* The sensor: exposure, lens blur, BT.601 limited-range conversion to I420 (chroma sited at the centre of
 * each 2x2 block, as C420jpeg says) and signal-dependent noise drawn from (seed, camera, frame)
 * alone, so frames can be made in any order or in parallel and stay byte-identical. */
typedef struct {
    double gain;       /* exposure */
    double read_noise; /* DN at black */
    uint64_t seed;
    const uint8_t *background[PHANTOM_MAX_CAMERAS]; /* RGB, shown where alpha is 0 */
} rd_sensor;

/* Fills the shared table of normal deviates; call once before any thread converts. */
void rd_sensor_init(void);
/* scratch: width * height bytes. */
void rd_sensor_to_i420(const rd_sensor *sn, int camera, int frame, const uint8_t *rgba, int width,
                       int height, uint8_t *i420, uint8_t *scratch);

/* The calibration target (board.c): a planar checkerboard of cols x rows inner corners (OpenCV's
 * patternSize), squares of `square` mm. Board frame: inner corner (r, c) at (c square, r square,
 * 0), as cv::calibrateCamera's object points; the square outside corner (0, 0) is black; the
 * printed face looks along -z. */
typedef struct {
    int cols, rows;
    double square;
} rd_board;

typedef struct {
    double R[9], t[3]; /* board -> world: X = R (u, v, 0) + t, mm */
} rd_board_pose;

/* "checkerboard:COLSxROWS:SQUARE_MM"; one count odd, one even (orientation unambiguous). */
sh_status rd_board_parse(const char *spec, rd_board *b);
/* World position of board point (u, v). */
void rd_board_point(const rd_board_pose *p, double u, double v, double X[3]);
/* n poses from the seed, each showing the whole board to every camera of m, tilted 15-40 degrees
 * in directions spread round the circle (every fifth nearly frontal). */
sh_status rd_board_poses(const phantom_model *m, const rd_board *b, int n, uint64_t seed,
                         rd_board_pose *out);

typedef struct rd_board_raster rd_board_raster;
/* Per camera c: the undistorted rays of the pixel corners (the lens is fixed). */
sh_status rd_board_raster_create(const phantom_model *m, int c, rd_board_raster **out);
void rd_board_raster_destroy(rd_board_raster *r);
/* The board in pose p seen by cam into rgba (alpha 255), drape (width x height RGB) around it;
 * each pixel the area average of what it sees. */
sh_status rd_board_draw(rd_board_raster *r, const phantom_camera *cam, const rd_board *b,
                        const rd_board_pose *p, const uint8_t *drape, uint8_t *rgba);

#endif
