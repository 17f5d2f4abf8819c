/* libFuzzer: arbitrary bytes as the phantom's parameter file (phantom.txt). The reader and the
 * model live with the phantom tool (tools/phantom), outside libstillheart, so they are compiled
 * in here (preset.c too, for the sticker sizes the model asks). A refusal names the file; an
 * accepted model has its counts in range, and evaluating the surface, a marker and a
 * projection on it must not trip a sanitizer. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../tools/phantom/camera.c"
#include "../../tools/phantom/model.c"
#include "../../tools/phantom/params.c"
#include "../../tools/phantom/preset.c"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static phantom_model m;
    if (phantom_model_parse((const char *)data, size, "fuzz.txt", &m) != SH_OK) {
        check(strncmp(sh_error_message(), "fuzz.txt", 8) == 0);
        return 0;
    }
    check(m.num_cameras >= 1 && m.num_cameras <= PHANTOM_MAX_CAMERAS);
    check(m.num_markers >= 0 && m.num_markers <= PHANTOM_MAX_MARKERS);
    check(m.num_blobs >= 0 && m.num_blobs <= PHANTOM_MAX_BLOBS);
    check(m.num_pads >= 0 && m.num_pads <= PHANTOM_MAX_PADS);
    double X[3], x, y;
    phantom_surface(&m, 1.5, -2.5, 0.3, X);
    (void)phantom_project(&m.cam[0], X, &x, &y);
    if (m.num_markers > 0) {
        phantom_marker_point(&m, 0, 2, 0.3, X);
        (void)phantom_marker_visible(&m, 0, 0.3, 0, 4);
    }
    return 0;
}
