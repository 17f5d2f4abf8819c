#include <stdlib.h>
#include <string.h>

#include "stab.h"
#include "stillheart/log.h"

int app_fail(const char *what)
{
    sh_log_error("%s%s%s", what, *sh_error_message() ? ": " : "",
                 sh_error_message());
    return 1;
}

int app_stab_start(app_stab *s, const char *command, const char *out_path, const sh_y4m_header *hdr)
{
    if (sh_y4m_writer_open(out_path, hdr, &s->writer) != SH_OK) return app_fail("output");
    /* a file's size says how many frames are to come; a pipe's does not (no total, no ETA) */
    long long rest = sh_y4m_reader_whole_frames(s->reader);
    long long total = rest < 0 ? 0 : sh_y4m_reader_frame_index(s->reader) + rest;
    sh_cli_progress_start(&s->progress, command, total > 1 << 30 ? 0 : (int)total, "frames");
    return 0;
}

int app_stab_run(app_stab *s, int (*step)(void *job), void *job, sh_status *st)
{
    while ((*st = sh_y4m_reader_read(s->reader, &s->in)) == SH_OK)
        if (step(job)) return 1;
    sh_cli_progress_end(&s->progress);
    if (*st != SH_EEOF) app_fail("input"); /* frames before the damage were written */
    sh_status closed = sh_y4m_writer_close(s->writer);
    s->writer = NULL;
    return closed != SH_OK ? app_fail("output") : 0;
}

void app_stab_raw(app_stab *s, const char *command, int n, int min, int quiet)
{
    s->raw_frames++;
    if (!quiet)
        fprintf(stderr, "%sstillheart %s: frame %d left unstabilized (%d markers%s%s)\n",
                s->progress.enabled ? "\n" : "", command, s->frames, n, n >= min ? ": " : "",
                n >= min ? sh_error_message() : "");
}

void app_stab_print_e(const app_stab *s, const char *out_path)
{
    if (!s->metric_in) return;
    double in = sh_metric_e(s->metric_in), out = sh_metric_e(s->metric_out);
    FILE *f = strcmp(out_path, "-") ? stdout : stderr;
    fprintf(f, "residual motion e (lower is better): %.6f -> %.6f", in, out);
    if (in > 0) fprintf(f, ", %+.0f %%", 100 * (out - in) / in); /* a still input has no change to give */
    fprintf(f, " (%d frames, %d hull pixels)\n", sh_metric_frames(s->metric_in), sh_metric_pixels(s->metric_in));
}

int app_stab_tag(sh_y4m_header *hdr, const char *kind, const sh_interp_params *a, const sh_interp_params *b)
{
    char na[32], nb[32], value[80];
    sh_interp_params_name(a, na, sizeof na);
    if (b) sh_interp_params_name(b, nb, sizeof nb);
    snprintf(value, sizeof value, "%s:%s%s%s", kind, na, b && strcmp(na, nb) ? "/" : "", b && strcmp(na, nb) ? nb : "");
    return sh_y4m_header_set_tag(hdr, SH_Y4M_STILLHEART, value) == SH_OK ? 0 : app_fail("output");
}

void app_stab_close(app_stab *s)
{
    if (s->writer) sh_y4m_writer_close(s->writer);
    sh_modelcache_destroy(s->cache);
    sh_y4m_reader_close(s->reader);
    sh_points_destroy(&s->points);
    sh_warp_destroy(s->warp);
    sh_metric_destroy(s->metric_in);
    sh_metric_destroy(s->metric_out);
    sh_image_destroy(&s->in);
    sh_image_destroy(&s->out);
    sh_image_destroy(&s->ref);
    free(s->ids);
    free(s->cur);
}
