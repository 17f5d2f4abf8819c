/* The scene drawn through OSMesa: the heart surface, its tags and blood blobs (all glued to
 * material coordinates and placed by phantom_surface), stabilizer pads, the instrument shaft,
 * the decoy card, and a drape behind.
 *
 * Vertices are projected here, on the CPU, through the same phantom_project() the truth uses,
 * lens distortion included, and handed to GL as clip coordinates (w = camera depth, so texture
 * interpolation stays perspective-correct). So a vertex lands exactly where the truth says; only
 * the inside of each ~6 px triangle is linear. Shading is per vertex: Lambert plus a Blinn-Phong
 * highlight passed as the secondary colour, added after texturing as wet tissue reflects.
 *
 * About 650 lines, on purpose: the meshes are made, moved and drawn through one rd_scene and one GL
 * context, and their layout (struct mesh, the grids' sizes) is private to this file; split, it
 * would have to go into a header shared by the parts. */
#define GL_GLEXT_PROTOTYPES 1 /* libOSMesa exports the GL 1.4 / 3.0 entry points we use */
#include <GL/osmesa.h>
#include <GL/gl.h>
#include <GL/glext.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "render.h"

#define GRID_U 81
#define GRID_V 65
#define TAG_GRID 9
#define BLOB_RINGS 5
#define BLOB_SEGS 48
#define NEAR_MM 20.0
#define FAR_MM 5000.0

typedef struct {
    float clip[4];
    float st[2];
    uint8_t col[4];
    uint8_t spec[4];
} vtx;

typedef struct {
    int n, ni;
    double *P, *N;   /* world positions and unit normals, 3n each */
    float *st;       /* texture coordinates, 2n */
    uint32_t *idx;
    GLuint tex;      /* 0: untextured, albedo only */
    float albedo[3]; /* 0..1 */
    float ka, kd, ks, shin;
    int offset;      /* polygon offset level: decals over the surface */
    int visible;
} mesh;

struct rd_scene {
    const phantom_model *m;
    OSMesaContext ctx;
    int width, height;
    mesh surface, tags[PHANTOM_MAX_MARKERS], blobs[PHANTOM_MAX_BLOBS], pads[PHANTOM_MAX_PADS];
    mesh shaft, card, decoy;
    GLuint tissue_tex, decoy_tex;
    GLuint tag_tex[PHANTOM_MAX_MARKERS];
    double card_rest[12], decoy_rest[12]; /* the card's and its tag's corners without camera motion */
    double pad_len[PHANTOM_MAX_PADS];     /* fixes each capsule's ring count (see capsule_alloc) */
    double rlim[PHANTOM_MAX_CAMERAS]; /* normalised radius beyond which distortion is frozen */
    double tag_half_extent; /* half the edge of a tag's image, white ring included, mm */
    vtx *buf;
    int buf_n;
    double t;
};

static sh_status mesh_alloc(mesh *me, int n, int ni)
{
    memset(me, 0, sizeof *me);
    me->n = n;
    me->ni = ni;
    me->P = calloc((size_t)n * 3, sizeof(double));
    me->N = calloc((size_t)n * 3, sizeof(double));
    me->st = calloc((size_t)n * 2, sizeof(float));
    me->idx = calloc((size_t)ni, sizeof(uint32_t));
    me->visible = 1;
    if (!me->P || !me->N || !me->st || !me->idx) return sh_error_set(SH_ENOMEM, "scene: out of memory");
    return SH_OK;
}

static void mesh_free(mesh *me)
{
    free(me->P);
    free(me->N);
    free(me->st);
    free(me->idx);
}

static void grid_indices(mesh *me, int nu, int nv)
{
    int k = 0;
    for (int j = 0; j + 1 < nv; j++)
        for (int i = 0; i + 1 < nu; i++) {
            uint32_t a = (uint32_t)(j * nu + i), b = a + 1, c = a + (uint32_t)nu, d = c + 1;
            me->idx[k++] = a, me->idx[k++] = b, me->idx[k++] = d;
            me->idx[k++] = a, me->idx[k++] = d, me->idx[k++] = c;
        }
}

static void material(mesh *me, float r, float g, float b, float ka, float kd, float ks, float shin)
{
    me->albedo[0] = r, me->albedo[1] = g, me->albedo[2] = b;
    me->ka = ka, me->kd = kd, me->ks = ks, me->shin = shin;
}

/* A capsule between a and b: a cylinder cut in pieces of ~4 mm so that distortion bends it,
 * closed by hemispheres. */
static sh_status capsule_alloc(mesh *me, double length, int *rings_out)
{
    int along = (int)(length / 4.0) + 2, cap = 6, segs = 20;
    int rings = along + 2 * cap;
    *rings_out = rings;
    sh_status st = mesh_alloc(me, rings * (segs + 1), (rings - 1) * segs * 6);
    if (st == SH_OK) grid_indices(me, segs + 1, rings);
    return st;
}

static void capsule_place(mesh *me, const double a[3], const double b[3], double r, double length)
{
    int along = (int)(length / 4.0) + 2, cap = 6, segs = 20, rings = along + 2 * cap;
    double ax[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double l = sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]);
    for (int i = 0; i < 3; i++) ax[i] /= l;
    double tmp[3] = {fabs(ax[2]) < 0.9 ? 0 : 1, 0, fabs(ax[2]) < 0.9 ? 1 : 0};
    double e1[3] = {ax[1] * tmp[2] - ax[2] * tmp[1], ax[2] * tmp[0] - ax[0] * tmp[2],
                    ax[0] * tmp[1] - ax[1] * tmp[0]};
    double l1 = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
    for (int i = 0; i < 3; i++) e1[i] /= l1;
    double e2[3] = {ax[1] * e1[2] - ax[2] * e1[1], ax[2] * e1[0] - ax[0] * e1[2],
                    ax[0] * e1[1] - ax[1] * e1[0]};
    for (int k = 0; k < rings; k++) {
        double s, rad, nz; /* position along the axis, ring radius, axial normal part */
        if (k < cap) {
            double ph = -M_PI / 2 + (M_PI / 2) * k / cap;
            s = r * sin(ph), rad = r * cos(ph), nz = sin(ph);
        } else if (k < cap + along) {
            s = l * (k - cap) / (along - 1), rad = r, nz = 0;
        } else {
            double ph = (M_PI / 2) * (k - cap - along + 1) / cap;
            s = l + r * sin(ph), rad = r * cos(ph), nz = sin(ph);
        }
        double nr = sqrt(fmax(0, 1 - nz * nz));
        for (int j = 0; j <= segs; j++) {
            double an = 2 * M_PI * j / segs, c = cos(an), sn = sin(an);
            double *P = me->P + 3 * (k * (segs + 1) + j), *N = me->N + 3 * (k * (segs + 1) + j);
            for (int i = 0; i < 3; i++) {
                double radial = c * e1[i] + sn * e2[i];
                P[i] = a[i] + s * ax[i] + rad * radial;
                N[i] = nz * ax[i] + nr * radial;
            }
        }
    }
}

static GLuint upload(const rd_texture *t, GLint min_filter)
{
    GLuint id;
    glGenTextures(1, &id);
    glBindTexture(GL_TEXTURE_2D, id);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, t->width, t->height, 0, GL_RGB, GL_UNSIGNED_BYTE, t->rgb);
    glGenerateMipmap(GL_TEXTURE_2D);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, min_filter);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    /* With the nearest mip level, a level still minified up to 1.4x makes bilinear edges
     * narrower than a pixel: aliased, and tag corners read from them scatter by 0.4 px. The
     * bias picks the coarser level, so texels are never smaller than pixels. */
    glTexParameterf(GL_TEXTURE_2D, GL_TEXTURE_LOD_BIAS, 0.5f);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    return id;
}

/* Radius up to which the camera's distortion is monotonic (phantom_model_build checked 1.3x the
 * image corners); beyond it vertices are distorted with the ratio frozen, so that geometry far
 * outside the view cannot fold back into it. */
static double distortion_limit(const phantom_camera *c, int w, int h)
{
    const double *d = c->dist;
    double rmax = 0;
    double corners[4][2] = {{0, 0}, {w, 0}, {0, h}, {w, h}};
    for (int i = 0; i < 4; i++) {
        double a = (corners[i][0] - c->cx) / c->fx, b = (corners[i][1] - c->cy) / c->fy;
        rmax = fmax(rmax, sqrt(a * a + b * b));
    }
    double prev = 0, r = 0;
    for (int i = 1; i <= 2000; i++) {
        r = rmax * 3.0 * i / 2000.0;
        double r2 = r * r, rd = r * (1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])));
        if (rd <= prev) return rmax * 3.0 * (i - 1) / 2000.0;
        prev = rd;
    }
    return r;
}

/* The tissue texture and one texture per marker; *total and *border: a tag image's width and
 * its black border's, in cells. */
static sh_status make_textures(rd_scene *s, const phantom_model *m, int *total, int *border)
{
    GLint maxtex = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxtex);
    sh_status st;
    rd_texture tex = {0};
    /* two texels per pixel of the patch's width on screen: enough for the mip chain to
     * filter, and small images start fast (tests render many) */
    double patch_px = m->cam[0].fx * m->size_u / 500.0;
    int tw = 512;
    while (tw < 2 * patch_px && tw < 4096 && tw < maxtex) tw *= 2;
    int th = (int)(tw * m->size_v / m->size_u);
    if ((st = rd_texture_tissue(m, tw, th, &tex)) != SH_OK) return st;
    /* --texture-filter trilinear: the nearest level switches where the heart's scale crosses a
     * level, and a seam between a sharper and a blurrier texture sweeps over the tissue, which
     * tissue has not (docs/landmarks.md, "The tail") */
    s->tissue_tex = upload(&tex, m->texture_trilinear ? GL_LINEAR_MIPMAP_LINEAR : GL_LINEAR_MIPMAP_NEAREST);
    rd_texture_free(&tex);
    *total = *border = 0;
    for (int i = 0; i < m->num_markers; i++) {
        if ((st = rd_texture_tag(m->family, m->marker[i].id, 16, &tex, total, border)) != SH_OK) return st;
        s->tag_tex[i] = upload(&tex, GL_LINEAR_MIPMAP_NEAREST);
        rd_texture_free(&tex);
    }
    return SH_OK;
}

/* The surface, a grid over the patch, and the tags, each a small grid over its whole image
 * (white ring included); their positions come with rd_scene_update. */
static sh_status make_surface_and_tags(rd_scene *s, const phantom_model *m)
{
    sh_status st;
    if ((st = mesh_alloc(&s->surface, GRID_U * GRID_V, (GRID_U - 1) * (GRID_V - 1) * 6)) != SH_OK) return st;
    grid_indices(&s->surface, GRID_U, GRID_V);
    for (int j = 0; j < GRID_V; j++)
        for (int i = 0; i < GRID_U; i++) {
            s->surface.st[2 * (j * GRID_U + i)] = (float)i / (GRID_U - 1);
            s->surface.st[2 * (j * GRID_U + i) + 1] = (float)j / (GRID_V - 1);
        }
    s->surface.tex = s->tissue_tex;
    material(&s->surface, 1, 1, 1, 0.30f, 0.80f, 0.45f, 45);

    for (int i = 0; i < m->num_markers; i++) {
        mesh *me = &s->tags[i];
        if ((st = mesh_alloc(me, TAG_GRID * TAG_GRID, (TAG_GRID - 1) * (TAG_GRID - 1) * 6)) != SH_OK) return st;
        grid_indices(me, TAG_GRID, TAG_GRID);
        for (int j = 0; j < TAG_GRID; j++)
            for (int k = 0; k < TAG_GRID; k++) {
                me->st[2 * (j * TAG_GRID + k)] = (float)k / (TAG_GRID - 1);
                me->st[2 * (j * TAG_GRID + k) + 1] = (float)j / (TAG_GRID - 1);
            }
        me->tex = s->tag_tex[i];
        me->offset = 1;
        material(me, 1, 1, 1, 0.30f, 0.80f, 0.08f, 20);
    }
    return SH_OK;
}

/* The blood blobs: a fan of rings each, placed by rd_scene_update. */
static sh_status make_blobs(rd_scene *s, const phantom_model *m)
{
    sh_status st;
    for (int b = 0; b < m->num_blobs; b++) {
        mesh *me = &s->blobs[b];
        int n = 1 + BLOB_RINGS * BLOB_SEGS;
        if ((st = mesh_alloc(me, n, BLOB_SEGS * 3 + (BLOB_RINGS - 1) * BLOB_SEGS * 6)) != SH_OK) return st;
        int k = 0;
        for (int j = 0; j < BLOB_SEGS; j++) {
            me->idx[k++] = 0, me->idx[k++] = (uint32_t)(1 + j), me->idx[k++] = (uint32_t)(1 + (j + 1) % BLOB_SEGS);
        }
        for (int r = 0; r + 1 < BLOB_RINGS; r++)
            for (int j = 0; j < BLOB_SEGS; j++) {
                uint32_t a = (uint32_t)(1 + r * BLOB_SEGS + j), b2 = (uint32_t)(1 + r * BLOB_SEGS + (j + 1) % BLOB_SEGS);
                uint32_t c = a + BLOB_SEGS, d = b2 + BLOB_SEGS;
                me->idx[k++] = a, me->idx[k++] = c, me->idx[k++] = d;
                me->idx[k++] = a, me->idx[k++] = d, me->idx[k++] = b2;
            }
        me->offset = 2;
        material(me, 0.42f, 0.02f, 0.04f, 0.35f, 0.75f, 0.9f, 80);
    }
    return SH_OK;
}

/* The stabilizer pads, placed once at rest, and the instrument shaft. */
static sh_status make_pads_and_shaft(rd_scene *s, const phantom_model *m)
{
    sh_status st;
    for (int p = 0; p < m->num_pads; p++) {
        double a[3], b[3];
        int rings;
        phantom_pad_axis(m, p, 0.0, a, b); /* rd_scene_update moves them with a camera motion */
        double len = sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
        s->pad_len[p] = len;
        if ((st = capsule_alloc(&s->pads[p], len, &rings)) != SH_OK) return st;
        capsule_place(&s->pads[p], a, b, m->pad_radius, len);
        material(&s->pads[p], 0.55f, 0.57f, 0.6f, 0.3f, 0.7f, 0.8f, 30);
    }
    if (m->shaft) {
        int rings;
        if ((st = capsule_alloc(&s->shaft, m->shaft_length, &rings)) != SH_OK) return st;
        material(&s->shaft, 0.5f, 0.52f, 0.55f, 0.3f, 0.7f, 1.0f, 40);
    }
    return SH_OK;
}

/* The decoy: the card, and the tag on it (a quad each: they are flat and rigid). */
static sh_status make_decoy(rd_scene *s, const phantom_model *m, int total, int border)
{
    sh_status st;
    rd_texture tex = {0};
    double half_card = 0.5 * phantom_decoy_card(m);
    double half_tag = 0.5 * m->tag_size * total / border;
    mesh *card = &s->card, *tag = &s->decoy;
    if ((st = mesh_alloc(card, 4, 6)) != SH_OK || (st = mesh_alloc(tag, 4, 6)) != SH_OK) return st;
    if ((st = rd_texture_tag(m->family, m->decoy_id, 16, &tex, &total, &border)) != SH_OK) return st;
    s->decoy_tex = upload(&tex, GL_LINEAR_MIPMAP_NEAREST);
    rd_texture_free(&tex);
    static const double su[4] = {-1, 1, 1, -1}, sv[4] = {1, 1, -1, -1};
    double c = cos(m->decoy_yaw), sn = sin(m->decoy_yaw);
    for (int k = 0; k < 4; k++) {
        double h2[2] = {half_card, half_tag};
        mesh *me2[2] = {card, tag};
        for (int q = 0; q < 2; q++) {
            double a = su[k] * h2[q], b = sv[k] * h2[q];
            me2[q]->P[3 * k] = m->decoy_center[0] + c * a - sn * b;
            me2[q]->P[3 * k + 1] = m->decoy_center[1] + sn * a + c * b;
            me2[q]->P[3 * k + 2] = m->decoy_center[2];
            me2[q]->N[3 * k + 2] = 1;
            me2[q]->st[2 * k] = su[k] > 0 ? 1.0f : 0.0f;
            me2[q]->st[2 * k + 1] = sv[k] > 0 ? 0.0f : 1.0f;
        }
    }
    memcpy(s->card_rest, card->P, sizeof s->card_rest);
    memcpy(s->decoy_rest, tag->P, sizeof s->decoy_rest);
    static const uint32_t quad[6] = {0, 1, 2, 0, 2, 3};
    memcpy(card->idx, quad, sizeof quad);
    memcpy(tag->idx, quad, sizeof quad);
    material(card, 0.93f, 0.93f, 0.9f, 0.35f, 0.7f, 0.05f, 10);
    material(tag, 1, 1, 1, 0.35f, 0.7f, 0.05f, 10);
    tag->tex = s->decoy_tex;
    tag->offset = 1;
    return SH_OK;
}

/* The fixed GL state every draw relies on. */
static void gl_setup(const phantom_model *m)
{
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LEQUAL);
    glEnable(GL_COLOR_SUM);
    glDisable(GL_LIGHTING);
    glDisable(GL_CULL_FACE);
    glTexEnvi(GL_TEXTURE_ENV, GL_TEXTURE_ENV_MODE, GL_MODULATE);
    glMatrixMode(GL_PROJECTION);
    glLoadIdentity();
    glMatrixMode(GL_MODELVIEW);
    glLoadIdentity();
    glViewport(0, 0, m->width, m->height);
    glEnableClientState(GL_VERTEX_ARRAY);
    glEnableClientState(GL_COLOR_ARRAY);
    glEnableClientState(GL_SECONDARY_COLOR_ARRAY);
    glEnableClientState(GL_TEXTURE_COORD_ARRAY);
}

sh_status rd_scene_create(const phantom_model *m, rd_scene **out)
{
    *out = NULL;
    rd_scene *s = calloc(1, sizeof *s);
    if (!s) return sh_error_set(SH_ENOMEM, "scene: out of memory");
    s->m = m;
    s->width = m->width;
    s->height = m->height;
    s->ctx = OSMesaCreateContextExt(OSMESA_RGBA, 24, 0, 0, NULL);
    if (!s->ctx) {
        free(s);
        return sh_error_set(SH_EUNSUPPORTED, "OSMesa: cannot create a context");
    }
    uint8_t *probe = malloc((size_t)m->width * m->height * 4);
    if (!probe || !OSMesaMakeCurrent(s->ctx, probe, GL_UNSIGNED_BYTE, m->width, m->height)) {
        free(probe);
        OSMesaDestroyContext(s->ctx);
        free(s);
        return sh_error_set(SH_EUNSUPPORTED, "OSMesa: cannot bind a %dx%d buffer", m->width, m->height);
    }
    OSMesaPixelStore(OSMESA_Y_UP, 0);
    free(probe);
    sh_status st;
    int total, border;
    if ((st = make_textures(s, m, &total, &border)) != SH_OK || (st = make_surface_and_tags(s, m)) != SH_OK)
        goto fail;
    s->tag_half_extent = 0.5 * m->tag_size * total / border;
    if ((st = make_blobs(s, m)) != SH_OK || (st = make_pads_and_shaft(s, m)) != SH_OK) goto fail;
    if (m->decoy && (st = make_decoy(s, m, total, border)) != SH_OK) goto fail;
    for (int c = 0; c < m->num_cameras; c++) s->rlim[c] = distortion_limit(&m->cam[c], m->width, m->height);

    int maxn = s->surface.n;
    if (s->shaft.n > maxn) maxn = s->shaft.n;
    for (int p = 0; p < m->num_pads; p++)
        if (s->pads[p].n > maxn) maxn = s->pads[p].n;
    s->buf = malloc(sizeof(vtx) * (size_t)maxn);
    if (!s->buf) {
        st = sh_error_set(SH_ENOMEM, "scene: out of memory");
        goto fail;
    }
    s->buf_n = maxn;

    gl_setup(m);
    *out = s;
    return SH_OK;
fail:
    rd_scene_destroy(s);
    return st;
}

void rd_scene_destroy(rd_scene *s)
{
    if (!s) return;
    mesh_free(&s->surface);
    for (int i = 0; i < PHANTOM_MAX_MARKERS; i++) mesh_free(&s->tags[i]);
    for (int i = 0; i < PHANTOM_MAX_BLOBS; i++) mesh_free(&s->blobs[i]);
    for (int i = 0; i < PHANTOM_MAX_PADS; i++) mesh_free(&s->pads[i]);
    mesh_free(&s->shaft);
    mesh_free(&s->card);
    mesh_free(&s->decoy);
    free(s->buf);
    if (s->ctx) OSMesaDestroyContext(s->ctx);
    free(s);
}

static void surface_vertex(const phantom_model *m, double u, double v, double t, double *P, double *N)
{
    phantom_surface(m, u, v, t, P);
    phantom_surface_normal(m, u, v, t, N);
}

/* The surface grid at time t, with shading normals from the grid itself: one surface evaluation
 * per vertex, not five. */
static void update_surface(rd_scene *s, const phantom_model *m, double t)
{
    mesh *sf = &s->surface;
    for (int j = 0; j < GRID_V; j++)
        for (int i = 0; i < GRID_U; i++) {
            double u = -0.5 * m->size_u + m->size_u * i / (GRID_U - 1);
            double v = -0.5 * m->size_v + m->size_v * j / (GRID_V - 1);
            phantom_surface(m, u, v, t, sf->P + 3 * (j * GRID_U + i));
        }
    for (int j = 0; j < GRID_V; j++)
        for (int i = 0; i < GRID_U; i++) {
            int i0 = i > 0 ? i - 1 : i, i1 = i + 1 < GRID_U ? i + 1 : i;
            int j0 = j > 0 ? j - 1 : j, j1 = j + 1 < GRID_V ? j + 1 : j;
            const double *a = sf->P + 3 * (j * GRID_U + i1), *b = sf->P + 3 * (j * GRID_U + i0);
            const double *c = sf->P + 3 * (j1 * GRID_U + i), *d = sf->P + 3 * (j0 * GRID_U + i);
            double eu[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
            double ev[3] = {c[0] - d[0], c[1] - d[1], c[2] - d[2]};
            double *n = sf->N + 3 * (j * GRID_U + i);
            n[0] = eu[1] * ev[2] - eu[2] * ev[1];
            n[1] = eu[2] * ev[0] - eu[0] * ev[2];
            n[2] = eu[0] * ev[1] - eu[1] * ev[0];
            double l = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            n[0] /= l, n[1] /= l, n[2] /= l;
        }
}

/* Each tag's grid on its tangent frame at time t. */
static void update_tags(rd_scene *s, const phantom_model *m, double t)
{
    double H = s->tag_half_extent;
    for (int k = 0; k < m->num_markers; k++) {
        mesh *me = &s->tags[k];
        double O[3], ea[3], eb[3];
        phantom_tag_frame(m, k, t, O, ea, eb);
        double n[3] = {ea[1] * eb[2] - ea[2] * eb[1], ea[2] * eb[0] - ea[0] * eb[2], ea[0] * eb[1] - ea[1] * eb[0]};
        double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int j = 0; j < TAG_GRID; j++)
            for (int i = 0; i < TAG_GRID; i++) {
                double a = -H + 2 * H * i / (TAG_GRID - 1);
                double b = H - 2 * H * j / (TAG_GRID - 1); /* image row 0 = top */
                double *P = me->P + 3 * (j * TAG_GRID + i), *N = me->N + 3 * (j * TAG_GRID + i);
                for (int q = 0; q < 3; q++) {
                    P[q] = O[q] + a * ea[q] + b * eb[q];
                    N[q] = n[q] / nl;
                }
            }
    }
}

/* The blood blobs at time t: hidden outside their lifetime, otherwise fans on the surface. */
static void update_blobs(rd_scene *s, const phantom_model *m, double t)
{
    for (int b = 0; b < m->num_blobs; b++) {
        mesh *me = &s->blobs[b];
        double r = phantom_blob_radius(m, b, t);
        me->visible = r > 0;
        if (!me->visible) continue;
        surface_vertex(m, m->blob[b].u, m->blob[b].v, t, me->P, me->N);
        for (int ring = 0; ring < BLOB_RINGS; ring++)
            for (int j = 0; j < BLOB_SEGS; j++) {
                double rr = r * (ring + 1) / BLOB_RINGS, an = 2 * M_PI * j / BLOB_SEGS;
                int q = 1 + ring * BLOB_SEGS + j;
                surface_vertex(m, m->blob[b].u + rr * cos(an), m->blob[b].v + rr * sin(an), t,
                               me->P + 3 * q, me->N + 3 * q);
            }
    }
}

void rd_scene_update(rd_scene *s, double t)
{
    const phantom_model *m = s->m;
    s->t = t;
    update_surface(s, m, t);
    update_tags(s, m, t);
    update_blobs(s, m, t);
    if (m->shaft) {
        double tip[3], end[3];
        phantom_shaft_axis(m, t, tip, end);
        capsule_place(&s->shaft, tip, end, m->shaft_radius, m->shaft_length);
    }
    /* the rigid things off the tissue move only with the camera */
    if (m->cam_motion != PHANTOM_CAM_NONE) {
        for (int p = 0; p < m->num_pads; p++) {
            double a[3], b[3];
            phantom_pad_axis(m, p, t, a, b);
            /* the length from creation: recomputed from the moved ends it could round across a
             * ring boundary and overrun the mesh */
            capsule_place(&s->pads[p], a, b, m->pad_radius, s->pad_len[p]);
        }
        if (m->decoy) {
            double d[3];
            phantom_camera_motion(m, t, d);
            for (int k = 0; k < 12; k++) {
                s->card.P[k] = s->card_rest[k] + d[k % 3];
                s->decoy.P[k] = s->decoy_rest[k] + d[k % 3];
            }
        }
    }
}

static void to_clip(const rd_scene *s, int c, const double P[3], float clip[4])
{
    const phantom_camera *cam = &s->m->cam[c];
    const double *R = cam->R;
    double zc = R[6] * P[0] + R[7] * P[1] + R[8] * P[2] + cam->t[2];
    double w = zc > 1e-3 ? zc : 1e-3;
    double x, y;
    double xc = R[0] * P[0] + R[1] * P[1] + R[2] * P[2] + cam->t[0];
    double yc = R[3] * P[0] + R[4] * P[1] + R[5] * P[2] + cam->t[1];
    double a = xc / w, b = yc / w, r = sqrt(a * a + b * b), lim = s->rlim[c];
    if (r <= lim && zc > 1e-3) {
        phantom_project(cam, P, &x, &y);
    } else {
        /* far outside the view: distort the point at the limit radius, keep the ratio */
        double k = lim / r, al = a * k, bl = b * k, r2 = lim * lim;
        const double *d = cam->dist;
        double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
        double xd = al * radial + 2.0 * d[2] * al * bl + d[3] * (r2 + 2.0 * al * al);
        double yd = bl * radial + d[2] * (r2 + 2.0 * bl * bl) + 2.0 * d[3] * al * bl;
        x = cam->fx * xd / k + cam->cx;
        y = cam->fy * yd / k + cam->cy;
    }
    /* OpenCV pixel centres are integers, GL's sit at +0.5; GL's y runs up */
    double xn = 2.0 * (x + 0.5) / s->width - 1.0;
    double yn = 2.0 * (s->height - (y + 0.5)) / s->height - 1.0;
    const double A = (FAR_MM + NEAR_MM) / (FAR_MM - NEAR_MM), B = -2.0 * FAR_MM * NEAR_MM / (FAR_MM - NEAR_MM);
    clip[0] = (float)(xn * w);
    clip[1] = (float)(yn * w);
    clip[2] = (float)(A * w + B);
    clip[3] = (float)w;
}

static const double LIGHT[3] = {40.0, 60.0, 700.0};

static void draw_mesh(rd_scene *s, int c, const mesh *me)
{
    if (!me->visible || me->n == 0) return;
    double C[3];
    phantom_camera_center(&s->m->cam[c], C);
    for (int i = 0; i < me->n; i++) {
        const double *P = me->P + 3 * i, *N = me->N + 3 * i;
        vtx *o = &s->buf[i];
        to_clip(s, c, P, o->clip);
        o->st[0] = me->st[2 * i];
        o->st[1] = me->st[2 * i + 1];
        double l[3] = {LIGHT[0] - P[0], LIGHT[1] - P[1], LIGHT[2] - P[2]};
        double v[3] = {C[0] - P[0], C[1] - P[1], C[2] - P[2]};
        double ll = sqrt(l[0] * l[0] + l[1] * l[1] + l[2] * l[2]);
        double vl = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        double h[3], hl = 0, ndl = 0;
        for (int k = 0; k < 3; k++) {
            l[k] /= ll;
            h[k] = l[k] + v[k] / vl;
            hl += h[k] * h[k];
            ndl += N[k] * l[k];
        }
        hl = sqrt(hl);
        double ndh = (N[0] * h[0] + N[1] * h[1] + N[2] * h[2]) / hl;
        double shade = me->ka + me->kd * (ndl > 0 ? ndl : 0);
        if (shade > 1) shade = 1;
        double spec = ndh > 0 && ndl > 0 ? me->ks * pow(ndh, me->shin) : 0;
        for (int k = 0; k < 3; k++) {
            o->col[k] = (uint8_t)(255.0 * me->albedo[k] * shade + 0.5);
            o->spec[k] = (uint8_t)(spec >= 1 ? 255 : 255.0 * spec * (k == 2 ? 0.92 : 1.0) + 0.5);
        }
        o->col[3] = 255;
        o->spec[3] = 0;
    }
    glVertexPointer(4, GL_FLOAT, sizeof(vtx), s->buf[0].clip);
    glTexCoordPointer(2, GL_FLOAT, sizeof(vtx), s->buf[0].st);
    glColorPointer(4, GL_UNSIGNED_BYTE, sizeof(vtx), s->buf[0].col);
    glSecondaryColorPointer(3, GL_UNSIGNED_BYTE, sizeof(vtx), s->buf[0].spec);
    if (me->tex) {
        glEnable(GL_TEXTURE_2D);
        glBindTexture(GL_TEXTURE_2D, me->tex);
    } else {
        glDisable(GL_TEXTURE_2D);
    }
    if (me->offset) {
        glEnable(GL_POLYGON_OFFSET_FILL);
        glPolygonOffset(-1.0f * me->offset, -4.0f * me->offset);
    } else {
        glDisable(GL_POLYGON_OFFSET_FILL);
    }
    glDrawElements(GL_TRIANGLES, me->ni, GL_UNSIGNED_INT, me->idx);
}

sh_status rd_scene_draw(rd_scene *s, int c, uint8_t *rgba)
{
    const phantom_model *m = s->m;
    if (!OSMesaMakeCurrent(s->ctx, rgba, GL_UNSIGNED_BYTE, s->width, s->height))
        return sh_error_set(SH_EIO, "OSMesa: cannot bind the frame buffer");
    OSMesaPixelStore(OSMESA_Y_UP, 0);
    /* alpha 0 marks background: the sensor stage fills it with the drape, which costs a lookup
     * there instead of a textured full-screen pass here */
    glClearColor(0, 0, 0, 0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    draw_mesh(s, c, &s->surface);
    /* A flat sticker on curved tissue dips below it by up to ~0.1 mm somewhere, and a blob on
     * the tissue may lie under a sticker's corner: both are drawn over what came before whatever
     * the depth (nothing but the tissue is drawn before them), and write their depth for the
     * occluders after them. */
    glDepthFunc(GL_ALWAYS);
    for (int i = 0; i < m->num_markers; i++) draw_mesh(s, c, &s->tags[i]);
    for (int b = 0; b < m->num_blobs; b++) draw_mesh(s, c, &s->blobs[b]);
    glDepthFunc(GL_LEQUAL);
    for (int p = 0; p < m->num_pads; p++) draw_mesh(s, c, &s->pads[p]);
    if (m->shaft) draw_mesh(s, c, &s->shaft);
    if (m->decoy) {
        draw_mesh(s, c, &s->card);
        draw_mesh(s, c, &s->decoy);
    }
    glFinish();
    GLenum err = glGetError();
    if (err != GL_NO_ERROR) return sh_error_set(SH_EIO, "OpenGL error 0x%x drawing camera %d", err, c);
    return SH_OK;
}
