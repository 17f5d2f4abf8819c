/* Frames the display tests can tell apart (test_display, test_display_view): frame n has every
 * byte a function of n and its position, so any mix of two frames shows, and a writer thread that
 * publishes frames 1..N of that kind as fast as it can. */
#ifndef STILLHEART_TEST_DISPLAY_PAINT_H
#define STILLHEART_TEST_DISPLAY_PAINT_H

#include <stdint.h>

#include "stillheart/display.h"

void paint(sh_image *img, uint32_t n);
/* Whether every byte of img is frame n's (n is periodic mod 256). */
int painted_as(const sh_image *img, uint32_t n);

typedef struct {
    sh_display_writer *w;
    int frames;
    int width, height; /* grey frames of this size */
} writer_job;

/* Publishes frames 1..job->frames (capture_ns n) into job->w; a pthread start routine. */
void *writer_main(void *job);

#endif
