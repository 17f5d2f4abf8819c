/* PLY export of the reference or current surface: a lattice in (X', Y') inside the markers'
 * hull, coloured from a camera's frame, optionally with the lattice's triangles. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/png.h"
#include "warp3d_internal.h"

#define VERTEX_BYTES 15 /* 3 float + 3 uchar */
#define FACE_BYTES 13   /* uchar 3 + 3 int */

struct sh_warp3d_ply {
    int count;          /* lattice points inside the hull */
    double *uv;         /* count x 2 */
    int faces;
    int *tri;           /* faces x 3 */
    unsigned char *buf; /* the whole body */
    size_t buf_size;
};

/* The model this exporter was built for is not stored: any model with the same hull can use it. */
sh_status sh_warp3d_ply_create(const sh_warp3d_model *m, double spacing, int mesh, sh_warp3d_ply **out)
{
    if (!m || !out || !(spacing > 0))
        return sh_error_set(SH_EINVAL, "warp3d: PLY spacing must be > 0 mm");
    const sh_hull *hull = &m->uv_hull;
    double w = hull->xmax - hull->xmin, h = hull->ymax - hull->ymin;
    if (w / spacing > 20000 || h / spacing > 20000 || (w / spacing + 1) * (h / spacing + 1) > 5e7)
        return sh_error_set(SH_ERANGE, "warp3d: PLY spacing %g mm gives too many points over "
                                       "%.1f x %.1f mm", spacing, w, h);
    int nu = (int)floor(w / spacing) + 1, nv = (int)floor(h / spacing) + 1;
    /* centre the lattice in the hull's box */
    double u0 = hull->xmin + (w - (nu - 1) * spacing) / 2, v0 = hull->ymin + (h - (nv - 1) * spacing) / 2;
    sh_warp3d_ply *p = calloc(1, sizeof *p);
    int *id = malloc(sizeof(int) * (size_t)nu * nv);
    if (!p || !id) {
        free(p);
        free(id);
        return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    }
    p->uv = malloc(sizeof(double) * 2 * (size_t)nu * nv);
    p->tri = mesh ? malloc(sizeof(int) * 6 * (size_t)nu * nv) : NULL;
    if (!p->uv || (mesh && !p->tri)) goto oom;
    for (int j = 0; j < nv; j++)
        for (int i = 0; i < nu; i++) {
            double u = u0 + i * spacing, v = v0 + j * spacing;
            id[j * nu + i] = -1;
            if (!sh_hull_contains(hull, u, v)) continue;
            p->uv[2 * p->count] = u;
            p->uv[2 * p->count + 1] = v;
            id[j * nu + i] = p->count++;
        }
    if (mesh) {
        for (int j = 0; j + 1 < nv; j++)
            for (int i = 0; i + 1 < nu; i++) {
                int a = id[j * nu + i], b = id[j * nu + i + 1], c = id[(j + 1) * nu + i + 1],
                    d = id[(j + 1) * nu + i];
                /* counter-clockwise seen from the normal's side (e1, e2, normal right-handed) */
                if (a >= 0 && b >= 0 && c >= 0) {
                    int *t = p->tri + 3 * p->faces++;
                    t[0] = a, t[1] = b, t[2] = c;
                }
                if (a >= 0 && c >= 0 && d >= 0) {
                    int *t = p->tri + 3 * p->faces++;
                    t[0] = a, t[1] = c, t[2] = d;
                }
            }
    }
    free(id);
    id = NULL;
    p->buf_size = (size_t)p->count * VERTEX_BYTES + (size_t)p->faces * FACE_BYTES;
    p->buf = malloc(p->buf_size + 1);
    if (!p->buf) goto oom;
    *out = p;
    return SH_OK;
oom:
    free(id);
    sh_warp3d_ply_destroy(p);
    return sh_error_set(SH_ENOMEM, "warp3d: out of memory for the PLY lattice");
}

void sh_warp3d_ply_destroy(sh_warp3d_ply *p)
{
    if (!p) return;
    free(p->uv);
    free(p->tri);
    free(p->buf);
    free(p);
}

int sh_warp3d_ply_num_points(const sh_warp3d_ply *p)
{
    return p->count;
}

static void put_f32(unsigned char *o, double v)
{
    float f = (float)v;
    uint32_t u;
    memcpy(&u, &f, 4);
    o[0] = (unsigned char)u, o[1] = (unsigned char)(u >> 8), o[2] = (unsigned char)(u >> 16),
    o[3] = (unsigned char)(u >> 24);
}

static void put_i32(unsigned char *o, int v)
{
    uint32_t u = (uint32_t)v;
    o[0] = (unsigned char)u, o[1] = (unsigned char)(u >> 8), o[2] = (unsigned char)(u >> 16),
    o[3] = (unsigned char)(u >> 24);
}

static void sample_rgb(const sh_image *rgb, double x, double y, unsigned char *out)
{
    if (!rgb || !(x >= 0 && y >= 0 && x <= rgb->width - 1 && y <= rgb->height - 1)) {
        out[0] = out[1] = out[2] = rgb ? 0 : 128;
        return;
    }
    int ix = (int)x, iy = (int)y;
    int ix1 = ix + 1 < rgb->width ? ix + 1 : ix, iy1 = iy + 1 < rgb->height ? iy + 1 : iy;
    double fx = x - ix, fy = y - iy;
    const uint8_t *r0 = rgb->plane[0].data + (size_t)iy * rgb->plane[0].stride;
    const uint8_t *r1 = rgb->plane[0].data + (size_t)iy1 * rgb->plane[0].stride;
    for (int c = 0; c < 3; c++) {
        double top = r0[3 * ix + c] * (1 - fx) + r0[3 * ix1 + c] * fx;
        double bot = r1[3 * ix + c] * (1 - fx) + r1[3 * ix1 + c] * fx;
        out[c] = (unsigned char)lrint(top * (1 - fy) + bot * fy);
    }
}

sh_status sh_warp3d_ply_write(sh_warp3d_ply *p, const sh_warp3d_model *m, int current,
                              const sh_image *rgb, const sh_calib_camera *cam, const char *path)
{
    if (!p || !m || !path) return sh_error_set(SH_EINVAL, "warp3d: PLY: missing argument");
    if (rgb && (rgb->format != SH_PIX_RGB24 || !cam))
        return sh_error_set(SH_EINVAL, "warp3d: PLY colour needs an RGB24 frame and its camera");
    unsigned char *o = p->buf;
    for (int k = 0; k < p->count; k++, o += VERTEX_BYTES) {
        double X[3], x = -1, y = -1;
        sh_warp3d_model_point(m, p->uv[2 * k], p->uv[2 * k + 1], 1, current, X);
        for (int c = 0; c < 3; c++) put_f32(o + 4 * c, X[c]);
        if (rgb && !sh_warp3d_project(cam, X, &x, &y)) x = y = -1;
        sample_rgb(rgb, x, y, o + 12);
    }
    for (int f = 0; f < p->faces; f++, o += FACE_BYTES) {
        o[0] = 3;
        for (int c = 0; c < 3; c++) put_i32(o + 1 + 4 * c, p->tri[3 * f + c]);
    }
    FILE *f = fopen(path, "wb");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot create", path);
    fprintf(f,
            "ply\nformat binary_little_endian 1.0\ncomment stillheart warp3d: %s surface, world mm\n"
            "element vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\n",
            current ? "stabilized current" : "reference", p->count);
    if (p->faces) fprintf(f, "element face %d\nproperty list uchar int vertex_indices\n", p->faces);
    fprintf(f, "end_header\n");
    size_t wrote = fwrite(p->buf, 1, p->buf_size, f);
    int bad = ferror(f);
    if (fclose(f) != 0 || bad || wrote != p->buf_size)
        return sh_error_set(SH_EIO, "%s: write failed", path);
    return SH_OK;
}

/* The textured mesh: OBJ + MTL + PNG, which every mesh viewer reads (PLY has no standard way to
 * name a texture). Texture coordinates are each vertex's pixel in cam, with OpenCV's pixel
 * centres at integers: s = (x + 0.5) / W, t = 1 - (y + 0.5) / H (OBJ's t runs up). */
sh_status sh_warp3d_obj_write(sh_warp3d_ply *p, const sh_warp3d_model *m, int current, const sh_image *rgb,
                              const sh_calib_camera *cam, const char *base)
{
    if (!p || !m || !rgb || !cam || !base) return sh_error_set(SH_EINVAL, "warp3d: OBJ: missing argument");
    if (!p->faces) return sh_error_set(SH_EINVAL, "warp3d: OBJ: the exporter was made without triangles");
    if (rgb->format != SH_PIX_RGB24) return sh_error_set(SH_EINVAL, "warp3d: OBJ texture must be RGB24");
    size_t n = strlen(base);
    char *path = malloc(n + 5);
    if (!path) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    const char *name = strrchr(base, '/');
    name = name ? name + 1 : base;
    sh_status st = SH_OK;
    snprintf(path, n + 5, "%s.png", base);
    if ((st = sh_png_write(path, rgb, 1)) != SH_OK) goto done;
    snprintf(path, n + 5, "%s.mtl", base);
    FILE *f = fopen(path, "w");
    if (!f) {
        st = sh_error_set(SH_EIO, "%s: cannot create", path);
        goto done;
    }
    fprintf(f, "newmtl frame\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd %s.png\n", name);
    if (fclose(f) != 0) {
        st = sh_error_set(SH_EIO, "%s: write failed", path);
        goto done;
    }
    snprintf(path, n + 5, "%s.obj", base);
    f = fopen(path, "w");
    if (!f) {
        st = sh_error_set(SH_EIO, "%s: cannot create", path);
        goto done;
    }
    fprintf(f, "# stillheart warp3d: %s surface, world mm, texture from the camera's frame\nmtllib %s.mtl\n",
            current ? "stabilized current" : "reference", name);
    for (int k = 0; k < p->count; k++) {
        double X[3];
        sh_warp3d_model_point(m, p->uv[2 * k], p->uv[2 * k + 1], 1, current, X);
        fprintf(f, "v %.5f %.5f %.5f\n", X[0], X[1], X[2]);
    }
    for (int k = 0; k < p->count; k++) {
        double X[3], x = -0.5, y = rgb->height - 0.5; /* behind the camera: texel (0, 0) */
        sh_warp3d_model_point(m, p->uv[2 * k], p->uv[2 * k + 1], 1, current, X);
        if (!sh_warp3d_project(cam, X, &x, &y)) x = -0.5, y = rgb->height - 0.5;
        fprintf(f, "vt %.7f %.7f\n", (x + 0.5) / rgb->width, 1.0 - (y + 0.5) / rgb->height);
    }
    fprintf(f, "usemtl frame\n");
    for (int t = 0; t < p->faces; t++) {
        const int *v = p->tri + 3 * t;
        fprintf(f, "f %d/%d %d/%d %d/%d\n", v[0] + 1, v[0] + 1, v[1] + 1, v[1] + 1, v[2] + 1, v[2] + 1);
    }
    int bad = ferror(f);
    if (fclose(f) != 0 || bad) st = sh_error_set(SH_EIO, "%s: write failed", path);
done:
    free(path);
    return st;
}
