/* The squeezed (half-resolution) stereo layouts: 3D monitors and televisions take one normal
 * frame holding both eyes, each at half the width (side by side) or half the height (top and
 * bottom), and stretch them back. Each eye is rendered at full size and halved here by
 * averaging pixel pairs (a box filter: what the squeeze must remove is above the new Nyquist
 * limit, and a pair average keeps every edge where it was). */
#include <string.h>

#include "warp3d_internal.h"

sh_status sh_warp3d_squeeze(const sh_image *full, int axis, sh_image *out, int ox, int oy)
{
    if (!full || !out || (axis != 0 && axis != 1) || full->format != out->format)
        return sh_error_set(SH_EINVAL, "warp3d squeeze: missing image, axis not 0 or 1, or formats differ");
    int sub = full->format == SH_PIX_I420; /* chroma at half resolution: the window must align on it */
    int align = sub ? 4 : 2;
    int w = axis == 0 ? full->width / 2 : full->width, h = axis == 1 ? full->height / 2 : full->height;
    if ((axis == 0 ? full->width : full->height) % align || ox < 0 || oy < 0 || ox + w > out->width ||
        oy + h > out->height || (sub && ((ox | oy) & 1)))
        return sh_error_set(SH_EINVAL, "warp3d squeeze: a %dx%d %s frame halved along %s needs a multiple of %d "
                            "there and room at (%d, %d) of %dx%d", full->width, full->height,
                            sh_pixfmt_name(full->format), axis ? "y" : "x", align, ox, oy, out->width, out->height);
    int channels = sh_pixfmt_channels(full->format);
    for (int p = 0; p < full->num_planes; p++) {
        const sh_plane *src = &full->plane[p];
        const sh_plane *dst = &out->plane[p];
        int chroma = sub && p > 0, c = p == 0 ? channels : 1;
        int px = chroma ? ox / 2 : ox, py = chroma ? oy / 2 : oy;
        int dw = axis == 0 ? src->width / 2 : src->width, dh = axis == 1 ? src->height / 2 : src->height;
        for (int y = 0; y < dh; y++) {
            uint8_t *o = dst->data + (size_t)(py + y) * dst->stride + (size_t)px * c;
            if (axis == 0) {
                const uint8_t *s = src->data + (size_t)y * src->stride;
                for (int x = 0; x < dw; x++)
                    for (int k = 0; k < c; k++) o[x * c + k] = (uint8_t)((s[2 * x * c + k] + s[(2 * x + 1) * c + k] + 1) >> 1);
            } else {
                const uint8_t *a = src->data + (size_t)(2 * y) * src->stride, *b = a + src->stride;
                for (int x = 0; x < dw * c; x++) o[x] = (uint8_t)((a[x] + b[x] + 1) >> 1);
            }
        }
    }
    return SH_OK;
}

static const char *const layout_names[SH_WARP3D_LAYOUT_COUNT] = {"sbs", "tb", "sbs-half", "tb-half"};

sh_status sh_warp3d_layout_parse(const char *name, sh_warp3d_layout *out)
{
    for (int l = 0; l < SH_WARP3D_LAYOUT_COUNT; l++)
        if (name && !strcmp(name, layout_names[l])) {
            *out = (sh_warp3d_layout)l;
            return SH_OK;
        }
    return sh_error_set(SH_EINVAL, "stereo layout '%s': sbs, tb, sbs-half or tb-half", name ? name : "");
}

const char *sh_warp3d_layout_name(sh_warp3d_layout layout)
{
    return layout >= 0 && layout < SH_WARP3D_LAYOUT_COUNT ? layout_names[layout] : "?";
}

int sh_warp3d_layout_half(sh_warp3d_layout layout) { return layout == SH_WARP3D_SBS_HALF || layout == SH_WARP3D_TB_HALF; }

/* 1 when the eyes are one above the other (tb, tb-half). */
static int top_bottom(sh_warp3d_layout layout) { return layout == SH_WARP3D_TB || layout == SH_WARP3D_TB_HALF; }

sh_status sh_warp3d_layout_size(sh_warp3d_layout layout, sh_pixfmt format, int width, int height, int *frame_width,
                                int *frame_height)
{
    if (layout < 0 || layout >= SH_WARP3D_LAYOUT_COUNT || width < 2 || height < 2)
        return sh_error_set(SH_EINVAL, "stereo layout: invalid layout or eye size %dx%d", width, height);
    int tb = top_bottom(layout), halved = tb ? height : width;
    int align = format == SH_PIX_I420 ? 4 : 2; /* sh_warp3d_squeeze's rule: halved chroma stays whole */
    if (sh_warp3d_layout_half(layout) && halved % align)
        return sh_error_set(SH_EINVAL, "stereo layout %s: the frame's %s (%d) must be a multiple of %d for %s frames",
                            layout_names[layout], tb ? "height" : "width", halved, align, sh_pixfmt_name(format));
    long fw = width, fh = height;
    if (!sh_warp3d_layout_half(layout)) {
        if (tb) fh *= 2;
        else fw *= 2;
    }
    if (fw > SH_IMAGE_MAX_SIZE || fh > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "stereo layout %s: the %ldx%ld frame of two %dx%d eyes is larger than %d px a side",
                            layout_names[layout], fw, fh, width, height, SH_IMAGE_MAX_SIZE);
    *frame_width = (int)fw;
    *frame_height = (int)fh;
    return SH_OK;
}

/* Where eye (0 left, 1 right) starts in the frame of a layout of width x height eyes. */
static void eye_origin(sh_warp3d_layout layout, int eye, int width, int height, int *ox, int *oy)
{
    int half = sh_warp3d_layout_half(layout), tb = top_bottom(layout);
    *ox = tb ? 0 : eye * (half ? width / 2 : width);
    *oy = tb ? eye * (half ? height / 2 : height) : 0;
}

sh_status sh_warp3d_layout_window(sh_warp3d_layout layout, int eye, const sh_image *frame, int width, int height,
                                  sh_image *view)
{
    if (sh_warp3d_layout_half(layout) || (eye != 0 && eye != 1))
        return sh_error_set(SH_EINVAL, "stereo layout %s: no full-size window for eye %d", sh_warp3d_layout_name(layout), eye);
    int ox, oy;
    eye_origin(layout, eye, width, height, &ox, &oy);
    return sh_image_window(frame, ox, oy, width, height, view);
}

sh_status sh_warp3d_layout_place(sh_warp3d_layout layout, int eye, const sh_image *eye_img, sh_image *frame)
{
    if (!eye_img || !frame || (eye != 0 && eye != 1) || layout < 0 || layout >= SH_WARP3D_LAYOUT_COUNT)
        return sh_error_set(SH_EINVAL, "stereo layout: missing image or no eye %d", eye);
    int ox, oy;
    eye_origin(layout, eye, eye_img->width, eye_img->height, &ox, &oy);
    if (sh_warp3d_layout_half(layout)) return sh_warp3d_squeeze(eye_img, top_bottom(layout), frame, ox, oy);
    sh_image view;
    sh_status st = sh_image_window(frame, ox, oy, eye_img->width, eye_img->height, &view);
    return st == SH_OK ? sh_image_copy(&view, eye_img) : st;
}

sh_status sh_warp3d_stereo_apply(sh_warp *warp, const sh_warp3d_view *const views[2], sh_warp_outside *const outside[2],
                                 sh_warp3d_layout layout, const sh_image *current, sh_image *eye, sh_image *frame)
{
    if (!views || !views[0] || !views[1] || !current || !frame || (sh_warp3d_layout_half(layout) && !eye))
        return sh_error_set(SH_EINVAL, "warp3d stereo: missing view or image");
    /* Eye 0 is done, outside fill included, before eye 1: whatever a row's last vector store of
     * the left window reaches beyond it lies in the right window, which is written after it. */
    for (int v = 0; v < 2; v++) {
        sh_image win;
        sh_status st = SH_OK;
        if (sh_warp3d_layout_half(layout)) win = *eye;
        else st = sh_warp3d_layout_window(layout, v, frame, current->width, current->height, &win);
        if (st == SH_OK) st = sh_warp3d_view_apply(warp, views[v], current, &win, 0, 0);
        if (st == SH_OK && outside && outside[v])
            st = sh_warp_outside_apply(outside[v], sh_warp3d_view_map_model(views[v]), current, &win);
        if (st == SH_OK && sh_warp3d_layout_half(layout)) st = sh_warp3d_layout_place(layout, v, eye, frame);
        if (st != SH_OK) return st;
    }
    return SH_OK;
}
