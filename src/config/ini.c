/* The daemon's INI files: inih when found, else a small built-in line parser with the same rules;
 * each key goes through sh_config_set (config.c), all or nothing. */
#include "stillheart/config.h"

#include "config_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef SH_HAVE_INIH
#include <ini.h>
#endif

typedef struct {
    sh_config *cfg;
    const char *origin;
    char *err;
    int failed;
    const char *next; /* inih's reader: the text left */
    int line;         /* the line the reader gave last: the one the handler's key is on */
} parse_ctx;

#ifdef SH_HAVE_INIH
/* Debian's inih calls the handler without a line number. inih counts a line per reader call,
 * so this reader (ini_parse_string's, which also cuts a line longer than num into several)
 * counts the same, and each key is set with its line: the refusal names it, and the config
 * records it for the checks after parsing (sh_config_where). */
static char *read_line(char *str, int num, void *stream)
{
    parse_ctx *c = stream;
    if (!*c->next || num < 2)
        return NULL;
    int n = 0;
    while (n < num - 1 && c->next[n] && (n == 0 || c->next[n - 1] != '\n'))
        n++;
    memcpy(str, c->next, (size_t)n);
    str[n] = 0;
    c->next += n;
    c->line++;
    return str;
}

static int on_key(void *user, const char *section, const char *name, const char *value)
{
    parse_ctx *c = user;
    if (c->failed)
        return 1; /* keep the first error */
    if (sh_config_set(c->cfg, section, name, value, c->origin, c->line, c->err) != SH_OK) {
        c->failed = 1;
        return 0;
    }
    return 1;
}
#endif

sh_status sh_config_parse_string(sh_config *cfg, const char *text, const char *origin, char *err)
{
    sh_config work = *cfg; /* all or nothing */
    parse_ctx c = {&work, origin, err, 0, text, 0};
    err[0] = 0;
#ifdef SH_HAVE_INIH
    int r = ini_parse_stream(read_line, &c, on_key, &c);
    if (c.failed)
        return SH_EINVAL;
    if (r != 0) {
        snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)",
                 origin, r > 0 ? r : 0);
        return SH_EFORMAT;
    }
#else
    (void)c; /* the handler's context, for inih */
    /* The same rules as inih's defaults: [section], key = value or key : value, ; and # comments. */
    char section[64] = "", line[1024];
    sh_lines it;
    sh_lines_init(&it, text, strlen(text), origin);
    sh_status st;
    while ((st = sh_lines_next(&it, line, sizeof line)) == SH_OK) {
        int lineno = it.lineno;
        char *s = line;
        while (*s == ' ' || *s == '\t' || *s == '\r')
            s++;
        char *e = s + strlen(s);
        while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r'))
            *--e = 0;
        if (!*s || *s == ';' || *s == '#')
            continue;
        if (*s == '[') {
            char *close = strchr(s, ']');
            if (!close || close - s - 1 >= (long)sizeof section) {
                snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)", origin, lineno);
                return SH_EFORMAT;
            }
            *close = 0;
            snprintf(section, sizeof section, "%s", s + 1);
            continue;
        }
        char *eq = strpbrk(s, "=:");
        if (!eq) {
            snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)", origin, lineno);
            return SH_EFORMAT;
        }
        *eq = 0;
        char *k = s, *v = eq + 1;
        char *ke = eq;
        while (ke > k && (ke[-1] == ' ' || ke[-1] == '\t'))
            *--ke = 0;
        while (*v == ' ' || *v == '\t')
            v++;
        char *c2 = strstr(v, " ;");
        if (c2) {
            *c2 = 0;
            char *ve = c2;
            while (ve > v && (ve[-1] == ' ' || ve[-1] == '\t'))
                *--ve = 0;
        }
        if (sh_config_set(&work, section, k, v, origin, lineno, err) != SH_OK)
            return SH_EINVAL;
    }
    if (st != SH_EEOF) { /* a line too long */
        snprintf(err, SH_CONFIG_ERR, "%s", sh_error_message());
        return st;
    }
#endif
    *cfg = work;
    return SH_OK;
}

sh_status sh_config_load_file(sh_config *cfg, const char *path, char *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, SH_CONFIG_ERR, "%s: cannot open: %s", path, strerror(errno));
        return SH_EIO;
    }
    char *text = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len + 4097 > cap) {
            cap = cap ? cap * 2 : 8192;
            if (cap > (1u << 20)) {
                free(text);
                fclose(f);
                snprintf(err, SH_CONFIG_ERR, "%s: larger than 1 MiB", path);
                return SH_EFORMAT;
            }
            char *t = realloc(text, cap);
            if (!t) {
                free(text);
                fclose(f);
                snprintf(err, SH_CONFIG_ERR, "%s: out of memory", path);
                return SH_ENOMEM;
            }
            text = t;
        }
        size_t got = fread(text + len, 1, 4096, f);
        len += got;
        if (got < 4096)
            break;
    }
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        free(text);
        snprintf(err, SH_CONFIG_ERR, "%s: read error", path);
        return SH_EIO;
    }
    text[len] = 0;
    if (strlen(text) != len) {
        free(text);
        snprintf(err, SH_CONFIG_ERR, "%s: contains a NUL byte", path);
        return SH_EFORMAT;
    }
    sh_status st = sh_config_parse_string(cfg, text, path, err);
    free(text);
    return st;
}
