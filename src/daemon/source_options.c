/* The config's cameras as the capture modules take them (daemon.h): source.h's options per
 * [cameraN], sync.h's for the set grouping, the [trigger] line, and the Y4M header of converted
 * frames. Shared by the daemon's cameras (run_source.c) and `stillheart record --config`. */
#include <stdio.h>
#include <string.h>

#include "run_source.h"
#include "stillheart/daemon.h"

int run_is_replay(const char *spec) { return !strncmp(spec, "y4m:", 4) || !strncmp(spec, "rec:", 4); }

_Static_assert(SH_CONFIG_CTRL_UNSET == SH_SOURCE_CTRL_UNSET, "config's unset control is source.h's");
_Static_assert(SH_CONFIG_MAX_CAMERAS <= SH_SYNC_MAX_CAMERAS, "every configured camera fits in a set");

void sh_daemon_camera_options(const sh_config *cfg, int i, sh_source_options *o)
{
    const sh_config_camera *c = &cfg->camera[i];
    sh_source_options_default(o);
    o->camera = i;
    o->width = c->width;
    o->height = c->height;
    sh_rawfmt f;
    if (c->format[0] && sh_rawfmt_parse(c->format, &f) == SH_OK) o->format = (int)f;
    o->fps_num = c->fps_num;
    o->fps_den = c->fps_den;
    o->timeout_ms = cfg->camera_timeout_ms;
    o->max_frame_pixels = cfg->max_frame_pixels;
    o->exposure = c->exposure;
    o->gain = c->gain;
    o->white_balance = c->white_balance;
    o->realtime = cfg->realtime;
    o->loop = cfg->loop;
}

double run_period_ns(int fps_num, int fps_den)
{
    return fps_num > 0 && fps_den > 0 ? 1e9 * fps_den / fps_num : 1e9 / 25; /* unknown: PAL's */
}

void sh_daemon_sync_options(const sh_config *cfg, int cameras, int fps_num, int fps_den, sh_sync_options *o)
{
    double p = run_period_ns(fps_num, fps_den);
    o->cameras = cameras;
    o->tolerance_ns = cfg->sync_tolerance_ms > 0 ? (int64_t)(cfg->sync_tolerance_ms * 1e6) : (int64_t)(p / 4);
    o->max_wait_ns = cfg->sync_wait_ms > 0 ? (int64_t)(cfg->sync_wait_ms * 1e6) : (int64_t)(2 * p);
    o->trigger_offset_ns = (int64_t)cfg->trigger_offset_us * 1000;
}

int sh_daemon_gpio_options(const sh_config *cfg, int fps_num, int fps_den, sh_gpio_options *o)
{
    memset(o, 0, sizeof *o);
    if (cfg->trigger == SH_TRIGGER_OFF) return 0;
    o->chip = cfg->trigger_chip;
    o->line = (unsigned)cfg->trigger_line;
    o->active_low = cfg->trigger_active_low;
    o->output = cfg->trigger == SH_TRIGGER_OUT;
    o->period_ns = cfg->trigger_fps > 0 ? (int64_t)(1e9 / cfg->trigger_fps) : (int64_t)run_period_ns(fps_num, fps_den);
    o->pulse_ns = (int64_t)cfg->trigger_pulse_us * 1000;
    return 1;
}

void sh_daemon_y4m_header(sh_rawfmt format, int width, int height, int fps_num, int fps_den, sh_y4m_header *h)
{
    memset(h, 0, sizeof *h);
    h->width = width;
    h->height = height;
    h->format = format == SH_RAW_GREY ? SH_PIX_GRAY8 : SH_PIX_I420;
    /* where pixconv puts the chroma (pixconv.h): 4:2:2 and NV12 keep theirs */
    h->siting = format == SH_RAW_YUYV || format == SH_RAW_NV12 ? SH_CHROMA_LEFT : SH_CHROMA_CENTER;
    h->fps_num = fps_num > 0 && fps_den > 0 ? fps_num : 25;
    h->fps_den = fps_num > 0 && fps_den > 0 ? fps_den : 1;
    h->interlace = 'p';
    if (format == SH_RAW_MJPEG) snprintf(h->extra, sizeof h->extra, "%s", SH_Y4M_FULL_RANGE);
}
