/* show-vmwriter: the writer of make vmtest's display check (tests/vm/show.sh), in the QEMU guest
 * only, never installed. Publishes a known frame to a display segment as the daemon would:
 *   show-vmwriter NAME SECONDS STATUS [REASON [FPS]]
 * 320x180 I420, limited range, FPS frames a second (default 10) for SECONDS, status stabilized |
 * degraded | raw with REASON, capture_ns 5 ms before publishing; then closes the segment (a
 * clean stop). Frames are due on a fixed schedule (start + k / FPS), not a sleep after each, so
 * that their rate does not drift with the time publishing takes (the latency check at 60 fps).
 * The pattern (tests/vm/show_check.py makes it again, independently, to compare the screen):
 *   Y(x, y) = 16 + (7x + 3y) mod 220, U(i, j) = 16 + 5i mod 225, V(i, j) = 16 + 9j mod 225
 * with (i, j) the chroma sample (x / 2, y / 2). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "stillheart/display.h"

#define W 320
#define H 180

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: show-vmwriter NAME SECONDS stabilized|degraded|raw [REASON [FPS]]\n");
        return 2;
    }
    double seconds = atof(argv[2]), fps = argc > 5 ? atof(argv[5]) : 10;
    if (!(fps > 0 && fps <= 1000)) {
        fprintf(stderr, "show-vmwriter: FPS '%s' is not in (0, 1000]\n", argv[5]);
        return 2;
    }
    uint32_t status = !strcmp(argv[3], "stabilized") ? SH_DISPLAY_STABILIZED
                      : !strcmp(argv[3], "degraded") ? SH_DISPLAY_DEGRADED : SH_DISPLAY_RAW;
    sh_image f;
    if (sh_image_create(&f, SH_PIX_I420, W, H) != SH_OK) return 1;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) f.plane[0].data[y * f.plane[0].stride + x] = (uint8_t)(16 + (7 * x + 3 * y) % 220);
    for (int j = 0; j < H / 2; j++)
        for (int i = 0; i < W / 2; i++) {
            f.plane[1].data[j * f.plane[1].stride + i] = (uint8_t)(16 + (5 * i) % 225);
            f.plane[2].data[j * f.plane[2].stride + i] = (uint8_t)(16 + (9 * j) % 225);
        }
    sh_display_writer *w;
    if (sh_display_writer_create(argv[1], SH_PIX_I420, W, H, 3, 0, NULL, &w) != SH_OK) {
        fprintf(stderr, "show-vmwriter: %s\n", sh_error_message());
        return 1;
    }
    sh_display_frame_info info;
    memset(&info, 0, sizeof info);
    info.status = status;
    info.markers_used = 16;
    info.residual_px = 0.5f;
    if (argc > 4) snprintf(info.reason, sizeof info.reason, "%s", argv[4]);
    const int64_t start = now_ns(), end = start + (int64_t)(seconds * 1e9);
    int n = 0;
    while (now_ns() < end) {
        info.capture_ns = now_ns() - 5000000;
        if (sh_display_writer_publish(w, &f, &info) != SH_OK) {
            fprintf(stderr, "show-vmwriter: %s\n", sh_error_message());
            return 1;
        }
        n++;
        int64_t due = start + (int64_t)((double)n * 1e9 / fps), wait = due - now_ns();
        if (wait > 0) nanosleep(&(struct timespec){(time_t)(wait / 1000000000), (long)(wait % 1000000000)}, NULL);
    }
    sh_display_writer_destroy(w, 0);
    sh_image_destroy(&f);
    fprintf(stderr, "show-vmwriter: %d frames published\n", n);
    return 0;
}
