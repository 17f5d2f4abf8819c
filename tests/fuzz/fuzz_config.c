/* libFuzzer: arbitrary bytes as the daemon's INI config. A refusal names the origin and leaves the
 * config untouched; anything accepted passes or fails sh_config_check cleanly and writes back to
 * INI that parses to the same config. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/config.h"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size + 1);
    if (!text) return 0;
    memcpy(text, data, size);
    text[size] = 0;
    sh_config c, before;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    before = c;
    if (sh_config_parse_string(&c, text, "fuzz.ini", err) != SH_OK) {
        check(strncmp(err, "fuzz.ini:", 9) == 0);
        check(memcmp(&c, &before, sizeof c) == 0);
        free(text);
        return 0;
    }
    free(text);
    check(c.threads >= 1 && c.threads <= 64 && c.slots >= 3 && c.slots <= 16);
    check(c.min_markers >= 1 && c.dropout_ms >= 0);
    check(memchr(c.sink, 0, sizeof c.sink) != NULL);
    for (int i = 0; i < SH_CONFIG_MAX_CAMERAS; i++) {
        const sh_config_camera *k = &c.camera[i];
        check(memchr(k->spec, 0, sizeof k->spec) && memchr(k->format, 0, sizeof k->format));
        check((k->width == 0) == (k->height == 0) && (k->fps_num == 0) == (k->fps_den == 0));
        check(k->fps_num >= 0 && k->fps_den >= 0);
    }
    check(c.output_camera >= 0 && c.output_camera < SH_CONFIG_MAX_CAMERAS);
    check(c.trigger >= SH_TRIGGER_OFF && c.trigger <= SH_TRIGGER_IN && memchr(c.trigger_chip, 0, sizeof c.trigger_chip));
    /* a refusal after parsing begins with where its key was set: this file's line, or no place */
    if (sh_config_check(&c, err) != SH_OK) check(memchr(err, 0, SH_CONFIG_ERR) != NULL);
    char where[SH_CONFIG_ERR];
    sh_config_where(&c, "method", "grid", where, sizeof where);
    check(!strncmp(where, "fuzz.ini:", 9) || !strcmp(where, "[method] grid"));
    /* write back and parse again: the same config (strings without newlines or comments only) */
    if (strpbrk(c.sink, "\n\r;#") || strpbrk(c.group, "\n\r;#") ||
        strpbrk(c.record, "\n\r;#") || strpbrk(c.points, "\n\r;#") || strpbrk(c.control, "\n\r;#") || strpbrk(c.family, "\n\r;#"))
        return 0;
    int clean = !strpbrk(c.trigger_chip, "\n\r;#");
    for (int i = 0; i < SH_CONFIG_MAX_CAMERAS; i++) clean &= !strpbrk(c.camera[i].spec, "\n\r;#");
    if (!clean) return 0;
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    if (!f) return 0;
    sh_config_write(&c, f);
    fclose(f);
    sh_config d;
    sh_config_default(&d);
    sh_status st = sh_config_parse_string(&d, buf, "written", err);
    free(buf);
    /* leading/trailing blanks in strings are trimmed by INI: strings not checked further; the
     * cameras' and trigger's numbers must come back as they were */
    if (st == SH_OK) {
        for (int i = 0; i < SH_CONFIG_MAX_CAMERAS; i++) {
            const sh_config_camera *a = &c.camera[i], *b = &d.camera[i];
            if (i > 0 && !a->spec[0]) continue; /* an absent camera is not written */
            check(a->width == b->width && a->height == b->height && a->fps_num == b->fps_num &&
                  a->fps_den == b->fps_den && a->exposure == b->exposure && a->gain == b->gain &&
                  a->white_balance == b->white_balance && !strcmp(a->format, b->format));
        }
        check(c.output_camera == d.output_camera && c.trigger == d.trigger && c.trigger_line == d.trigger_line &&
              c.trigger_active_low == d.trigger_active_low && c.trigger_fps == d.trigger_fps &&
              c.trigger_pulse_us == d.trigger_pulse_us && c.trigger_offset_us == d.trigger_offset_us &&
              c.sync_tolerance_ms == d.sync_tolerance_ms && c.sync_wait_ms == d.sync_wait_ms &&
              c.camera_timeout_ms == d.camera_timeout_ms);
    }
    return 0;
}
