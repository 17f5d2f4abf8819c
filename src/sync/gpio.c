/* GPIO trigger lines through libgpiod 1.6 (the v1 API), sync.h. Output pulses are timed by a
 * timerfd that alternates between the rising and the falling edge of each pulse; input edges
 * come from the line's event fd with the kernel's CLOCK_MONOTONIC timestamps (Linux >= 5.7). */
#include "stillheart/sync.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef SH_HAVE_GPIOD
#include <gpiod.h>
#include <sys/timerfd.h>
#include <unistd.h>

struct sh_gpio_trigger {
    sh_gpio_options o;
    char chip_name[64];
    struct gpiod_chip *chip;
    struct gpiod_line *line;
    int tfd;
    int64_t t0;
    uint64_t k;        /* next pulse */
    int high;          /* output currently active */
    uint64_t edges;
};

static void arm_at(int tfd, int64_t t)
{
    struct itimerspec it;
    memset(&it, 0, sizeof it);
    it.it_value.tv_sec = (time_t)(t / 1000000000);
    it.it_value.tv_nsec = (long)(t % 1000000000);
    if (!it.it_value.tv_sec && !it.it_value.tv_nsec) it.it_value.tv_nsec = 1;
    timerfd_settime(tfd, TFD_TIMER_ABSTIME, &it, NULL);
}

sh_status sh_gpio_trigger_open(const sh_gpio_options *o, sh_gpio_trigger **out)
{
    if (!o || !out || !o->chip) return sh_error_set(SH_EINVAL, "gpio: no chip named");
    if (o->output && (o->pulse_ns <= 0 || o->period_ns <= o->pulse_ns))
        return sh_error_set(SH_EINVAL, "gpio %s line %u: pulse width must be positive and under the period", o->chip,
                            o->line);
    sh_gpio_trigger *t = calloc(1, sizeof *t);
    if (!t) return sh_error_set(SH_ENOMEM, "gpio: out of memory");
    t->o = *o;
    t->tfd = -1;
    snprintf(t->chip_name, sizeof t->chip_name, "%s", o->chip);
    t->o.chip = t->chip_name;
    sh_status st;
    t->chip = gpiod_chip_open_lookup(o->chip);
    if (!t->chip) {
        st = sh_error_set(SH_EIO, "gpio chip %s: %s", o->chip, errno ? strerror(errno) : "not found");
        goto fail;
    }
    if (o->line >= gpiod_chip_num_lines(t->chip)) {
        st = sh_error_set(SH_EINVAL, "gpio chip %s: no line %u (it has %u)", o->chip, o->line,
                          gpiod_chip_num_lines(t->chip));
        goto fail;
    }
    t->line = gpiod_chip_get_line(t->chip, o->line);
    if (!t->line) {
        st = sh_error_set(SH_EIO, "gpio chip %s line %u: %s", o->chip, o->line, strerror(errno));
        goto fail;
    }
    int flags = o->active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    int r = o->output ? gpiod_line_request_output_flags(t->line, "stillheart", flags, 0)
                      : gpiod_line_request_rising_edge_events_flags(t->line, "stillheart", flags);
    if (r < 0) {
        int e = errno;
        st = sh_error_set(SH_EIO, "gpio chip %s line %u: %s", o->chip, o->line,
                          e == EBUSY ? "busy (another consumer holds it)" : strerror(e));
        goto fail;
    }
    if (o->output) {
        t->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
        if (t->tfd < 0) {
            st = sh_error_set(SH_EIO, "gpio: timerfd: %s", strerror(errno));
            goto fail;
        }
    }
    *out = t;
    return SH_OK;
fail:
    sh_gpio_trigger_close(t);
    return st;
}

sh_status sh_gpio_trigger_start(sh_gpio_trigger *t)
{
    if (!t) return sh_error_set(SH_EINVAL, "gpio: NULL");
    if (!t->o.output) return SH_OK;
    t->t0 = sh_monotonic_ns();
    t->k = 0;
    t->high = 0;
    arm_at(t->tfd, t->t0);
    return SH_OK;
}

int sh_gpio_trigger_fd(const sh_gpio_trigger *t)
{
    if (!t) return -1;
    return t->o.output ? t->tfd : gpiod_line_event_get_fd(t->line);
}

sh_status sh_gpio_trigger_service(sh_gpio_trigger *t, int64_t *edge_ns, int *got)
{
    if (!t || !edge_ns || !got) return sh_error_set(SH_EINVAL, "gpio: NULL argument");
    *got = 0;
    if (!t->o.output) {
        struct timespec zero = {0, 0};
        int r = gpiod_line_event_wait(t->line, &zero);
        if (r < 0) return sh_error_set(SH_EIO, "gpio chip %s line %u: %s", t->o.chip, t->o.line, strerror(errno));
        if (r == 0) return SH_OK;
        struct gpiod_line_event ev;
        if (gpiod_line_event_read(t->line, &ev) < 0)
            return sh_error_set(SH_EIO, "gpio chip %s line %u: %s", t->o.chip, t->o.line, strerror(errno));
        *edge_ns = (int64_t)ev.ts.tv_sec * 1000000000 + ev.ts.tv_nsec;
        *got = ev.event_type == GPIOD_LINE_EVENT_RISING_EDGE;
        if (*got) t->edges++;
        return SH_OK;
    }
    uint64_t exp;
    if (read(t->tfd, &exp, sizeof exp) < 0) return SH_OK; /* not due */
    int64_t rise = t->t0 + (int64_t)t->k * t->o.period_ns;
    if (!t->high) {
        if (gpiod_line_set_value(t->line, 1) < 0)
            return sh_error_set(SH_EIO, "gpio chip %s line %u: %s", t->o.chip, t->o.line, strerror(errno));
        *edge_ns = sh_monotonic_ns();
        *got = 1;
        t->edges++;
        t->high = 1;
        arm_at(t->tfd, rise + t->o.pulse_ns);
    } else {
        if (gpiod_line_set_value(t->line, 0) < 0)
            return sh_error_set(SH_EIO, "gpio chip %s line %u: %s", t->o.chip, t->o.line, strerror(errno));
        t->high = 0;
        /* the next pulse on the schedule; pulses missed while the caller was away are skipped */
        int64_t now = sh_monotonic_ns();
        do t->k++;
        while (t->t0 + (int64_t)t->k * t->o.period_ns < now);
        arm_at(t->tfd, t->t0 + (int64_t)t->k * t->o.period_ns);
    }
    return SH_OK;
}

uint64_t sh_gpio_trigger_edges(const sh_gpio_trigger *t) { return t ? t->edges : 0; }

void sh_gpio_trigger_close(sh_gpio_trigger *t)
{
    if (!t) return;
    if (t->line) gpiod_line_release(t->line);
    if (t->chip) gpiod_chip_close(t->chip);
    if (t->tfd >= 0) close(t->tfd);
    free(t);
}

#else /* no libgpiod */

struct sh_gpio_trigger {
    int unused;
};

sh_status sh_gpio_trigger_open(const sh_gpio_options *o, sh_gpio_trigger **out)
{
    (void)out;
    return sh_error_set(SH_EUNSUPPORTED, "gpio chip %s: built without libgpiod", o && o->chip ? o->chip : "?");
}
sh_status sh_gpio_trigger_start(sh_gpio_trigger *t)
{
    (void)t;
    return sh_error_set(SH_EUNSUPPORTED, "gpio: built without libgpiod");
}
int sh_gpio_trigger_fd(const sh_gpio_trigger *t)
{
    (void)t;
    return -1;
}
sh_status sh_gpio_trigger_service(sh_gpio_trigger *t, int64_t *edge_ns, int *got)
{
    (void)t;
    (void)edge_ns;
    if (got) *got = 0;
    return sh_error_set(SH_EUNSUPPORTED, "gpio: built without libgpiod");
}
uint64_t sh_gpio_trigger_edges(const sh_gpio_trigger *t)
{
    (void)t;
    return 0;
}
void sh_gpio_trigger_close(sh_gpio_trigger *t) { (void)t; }
#endif
