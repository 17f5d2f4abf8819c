/* Ground-truth correspondences: the points file `stillheart warp` reads, made of the tag centres
 * the renderer wrote, so Table II can be reproduced with perfect tracking (detection is judged on
 * its own). */
#include <stdio.h>
#include <stdlib.h>

#include "eval.h"

static int by_frame_id(const void *a, const void *b)
{
    const sh_point *p = a, *q = b;
    if (p->frame != q->frame) return (p->frame > q->frame) - (p->frame < q->frame);
    return (p->id > q->id) - (p->id < q->id);
}

sh_status eval_export_points(const char *dir, int camera, FILE *out, const char *out_name)
{
    char path[4096];
    if (snprintf(path, sizeof path, "%s/markers.csv", dir) >= (int)sizeof path)
        return sh_error_set(SH_EINVAL, "%s: path too long", dir);
    phantom_csv csv = {0};
    sh_status st = phantom_csv_read(path, &csv);
    if (st != SH_OK) return st;
    sh_point *rows = malloc(sizeof(sh_point) * (size_t)(csv.count + 1));
    if (!rows) {
        phantom_csv_free(&csv);
        return sh_error_set(SH_ENOMEM, "%s: out of memory", path);
    }
    int n = 0, cam_rows = 0;
    for (int i = 0; i < csv.count; i++) {
        const phantom_csv_row *r = &csv.rows[i];
        if (r->camera != camera) continue;
        cam_rows++;
        if (r->point != PHANTOM_POINTS - 1 || !r->visible) continue;
        rows[n++] = (sh_point){.frame = r->frame, .id = r->id, .x = r->x, .y = r->y,
                               .X = r->X, .Y = r->Y, .Z = r->Z};
    }
    phantom_csv_free(&csv);
    if (cam_rows == 0) {
        free(rows);
        return sh_error_set(SH_EINVAL, "%s: no rows for camera %d", path, camera);
    }
    qsort(rows, (size_t)n, sizeof *rows, by_frame_id);
    st = sh_points_write(out, rows, n, 1);
    free(rows);
    if (st != SH_OK) {
        char why[512]; /* the message buffer is the one sh_error_set writes */
        snprintf(why, sizeof why, "%s", sh_error_message());
        return sh_error_set(st, "%s: %s", out_name, why);
    }
    return SH_OK;
}
