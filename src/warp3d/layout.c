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
