/* The command-line conventions every program shares: include/stillheart/cli.h. */
#include <errno.h>
#include <pwd.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "stillheart/cli.h"
#include "stillheart/log.h"
#include "stillheart/core.h"

int sh_cli_usage_error(const sh_cli *cli, const char *fmt, ...)
{
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    sh_log_error("%s; try '%s --help'", msg, cli->command);
    return 2;
}

int sh_cli_set_log_level(const char *text)
{
    static const struct {
        const char *name;
        sh_log_level level;
    } names[] = {{"error", SH_LOG_ERROR}, {"warning", SH_LOG_WARN}, {"warn", SH_LOG_WARN},
                 {"info", SH_LOG_INFO},   {"debug", SH_LOG_DEBUG}};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (!strcasecmp(text, names[i].name)) {
            sh_log_set_level(names[i].level);
            return 1;
        }
    return 0;
}

int sh_cli_parse_bool(const char *text, int *out)
{
    static const char *const yes[] = {"1", "yes", "true", "on"}, *const no[] = {"0", "no", "false", "off"};
    for (int i = 0; i < 4; i++) {
        if (!strcasecmp(text, yes[i])) return *out = 1;
        if (!strcasecmp(text, no[i])) return !(*out = 0);
    }
    return 0;
}

int sh_cli_parse_int(const char *option, const char *text, int min, int max, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (errno || end == text || *end || v < min || v > max) {
        sh_log_error("%s: '%s' is not a whole number in %d..%d", option, text, min, max);
        return 0;
    }
    *out = (int)v;
    return 1;
}

int sh_cli_parse_user(const char *option, const char *text, int64_t *uid)
{
    char *end;
    long v = strtol(text, &end, 10);
    struct passwd *pw = getpwnam(text);
    if (pw) {
        *uid = pw->pw_uid;
    } else if (*text && !*end && v >= 0 && v < 0x7fffffffL) {
        *uid = v;
    } else {
        sh_log_error("%s: no user '%s'", option, text);
        return 0;
    }
    return 1;
}

int sh_cli_parse_double(const char *option, const char *text, double min, double max, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (errno || end == text || *end || !isfinite(v) || v < min || v > max) {
        sh_log_error("%s: '%s' is not a number in %g..%g", option, text, min, max);
        return 0;
    }
    *out = v;
    return 1;
}

/* The argument getopt_long stopped at: argv[optind - 1], unless a value option's name and value
 * were one word. */
static const char *offending(char **argv)
{
    const char *a = argv[optind - 1];
    return a ? a : "";
}

int sh_cli_option(const sh_cli *cli, int ch, char **argv)
{
    switch (ch) {
    case SH_CLI_VERSION: printf("%s %s\n", cli->command, SH_VERSION); return 0;
    case SH_CLI_LOG_LEVEL:
        if (sh_cli_set_log_level(optarg)) return -1;
        return sh_cli_usage_error(cli, "--log-level: '%s' is not error, warning, info or debug", optarg);
    case SH_CLI_QUIET: sh_log_set_level(SH_LOG_WARN); return -1;
    case ':': return sh_cli_usage_error(cli, "option '%s' needs a value", offending(argv));
    default:
        if (strncmp(offending(argv), "--", 2) && optopt > 0 && optopt < 0x100)
            return sh_cli_usage_error(cli, "unknown option '-%c'", optopt);
        if (!strncmp(offending(argv), "--", 2) && strchr(offending(argv), '=')) {
            /* glibc names the option in optopt when it takes no value; an unknown one is 0 */
            int n = (int)(strchr(offending(argv), '=') - offending(argv));
            return sh_cli_usage_error(cli, optopt ? "option '%.*s' takes no value" : "unknown option '%.*s'", n,
                                      offending(argv));
        }
        return sh_cli_usage_error(cli, "unknown option '%s'", offending(argv));
    }
}

/* ---- progress ---- */
void sh_cli_progress_start(sh_cli_progress *p, const char *label, int total, const char *unit)
{
    p->enabled = isatty(STDERR_FILENO) && sh_log_get_level() >= SH_LOG_INFO;
    p->total = total;
    p->label = label;
    p->unit = unit ? unit : "frames";
    p->start = p->last = (double)sh_monotonic_ns() * 1e-9;
}

void sh_cli_progress_update(sh_cli_progress *p, int done)
{
    if (!p->enabled) return;
    double now = (double)sh_monotonic_ns() * 1e-9;
    if (now - p->last < 0.1 && done != p->total) return;
    p->last = now;
    double rate = done / fmax(now - p->start, 1e-9);
    if (p->total > 0) {
        int width = 30, fill = (int)((long)width * (done < p->total ? done : p->total) / p->total);
        char eta[32] = "";
        if (done > 0 && done < p->total) {
            long s = lrint((p->total - done) / rate);
            snprintf(eta, sizeof eta, "  ETA %ld:%02ld", s / 60, s % 60);
        }
        fprintf(stderr, "\r%s [%.*s%*s] %d/%d  %.1f %s/s%s   ", p->label, fill,
                "##############################", width - fill, "", done, p->total, rate, p->unit, eta);
    } else {
        fprintf(stderr, "\r%s %d %s  %.1f %s/s ", p->label, done, p->unit, rate, p->unit);
    }
}

void sh_cli_progress_end(sh_cli_progress *p)
{
    if (p->enabled) fputc('\n', stderr);
    p->enabled = 0;
}

/* ---- JSON ---- */
static void json_quoted(FILE *out, const char *s)
{
    fputc('"', out);
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') fprintf(out, "\\%c", c);
        else if (c < 0x20 || c == 0x7f) fprintf(out, "\\u%04x", c);
        else fputc(c, out);
    }
    fputc('"', out);
}

/* The comma before every member but the first, and the member's name. */
static void json_key(sh_cli_json *j, const char *key)
{
    if (j->depth > 0 && j->count[j->depth - 1]++) fputs(", ", j->out);
    if (key) {
        json_quoted(j->out, key);
        fputs(": ", j->out);
    }
}

void sh_cli_json_start(sh_cli_json *j, FILE *out)
{
    memset(j, 0, sizeof *j);
    j->out = out;
}

static void json_open(sh_cli_json *j, const char *key, char open, char close)
{
    json_key(j, key);
    fputc(open, j->out);
    if (j->depth < (int)sizeof j->close) {
        j->close[j->depth] = close;
        j->count[j->depth] = 0;
        j->depth++;
    }
}

void sh_cli_json_object(sh_cli_json *j, const char *key) { json_open(j, key, '{', '}'); }
void sh_cli_json_array(sh_cli_json *j, const char *key) { json_open(j, key, '[', ']'); }

void sh_cli_json_end(sh_cli_json *j)
{
    if (j->depth > 0) fputc(j->close[--j->depth], j->out);
    if (j->depth == 0) fputc('\n', j->out);
}

void sh_cli_json_string(sh_cli_json *j, const char *key, const char *s)
{
    json_key(j, key);
    if (s) json_quoted(j->out, s);
    else fputs("null", j->out);
}

void sh_cli_json_number(sh_cli_json *j, const char *key, double v)
{
    json_key(j, key);
    if (isfinite(v)) fprintf(j->out, "%.17g", v);
    else fputs("null", j->out);
}

void sh_cli_json_int(sh_cli_json *j, const char *key, long long v)
{
    json_key(j, key);
    fprintf(j->out, "%lld", v);
}

void sh_cli_json_bool(sh_cli_json *j, const char *key, int v)
{
    json_key(j, key);
    fputs(v ? "true" : "false", j->out);
}

void sh_cli_json_null(sh_cli_json *j, const char *key)
{
    json_key(j, key);
    fputs("null", j->out);
}
