/* display_paint.h */
#include "display_paint.h"

void paint(sh_image *img, uint32_t n)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width; x++)
                img->plane[p].data[(size_t)y * img->plane[p].stride + x] =
                    (uint8_t)(n * 31u + (uint32_t)(x * 7 + y * 13 + p * 101));
}

int painted_as(const sh_image *img, uint32_t n)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width; x++)
                if (img->plane[p].data[(size_t)y * img->plane[p].stride + x] !=
                    (uint8_t)(n * 31u + (uint32_t)(x * 7 + y * 13 + p * 101)))
                    return 0;
    return 1;
}

void *writer_main(void *arg)
{
    writer_job *job = arg;
    sh_image img;
    if (sh_image_create(&img, SH_PIX_GRAY8, job->width, job->height) != SH_OK) return NULL;
    for (int n = 1; n <= job->frames; n++) {
        paint(&img, (uint32_t)n);
        sh_display_writer_publish(job->w, &img, &(sh_display_frame_info){.capture_ns = n});
    }
    sh_image_destroy(&img);
    return NULL;
}
