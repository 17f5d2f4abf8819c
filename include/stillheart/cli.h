/* The command-line conventions every program shares (the `stillheart` command and its
 * subcommands, the tools): --help, --version, --log-level, boolean option values, the one-line
 * usage error, the progress line and JSON output.
 *
 * For programs only, as log.h: the library never includes this header (it prints).
 *
 * A program's getopt_long loop takes the common options from SH_CLI_OPTIONS and hands every case
 * it does not know to sh_cli_option:
 *     static const struct option opts[] = {..., SH_CLI_OPTIONS, {0, 0, 0, 0}};
 *     opterr = 0;
 *     while ((ch = getopt_long(argc, argv, ":", opts, NULL)) != -1)
 *         switch (ch) {
 *         ...
 *         case 'h': usage(stdout); return 0;
 *         default: { int rc = sh_cli_option(&cli, ch, argv); if (rc >= 0) return rc; }
 *         }
 * (":" makes a missing value its own case, so the message names it.) */
#ifndef STILLHEART_CLI_H
#define STILLHEART_CLI_H

#include <getopt.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The version every program reports (debian/changelog's upstream part). */
#define SH_VERSION "0.1.0"

/* getopt_long values of the common options (above any character). */
enum { SH_CLI_VERSION = 0x1000, SH_CLI_LOG_LEVEL, SH_CLI_QUIET };
#define SH_CLI_OPTIONS                                                                            \
    {"help", no_argument, 0, 'h'}, {"version", no_argument, 0, SH_CLI_VERSION},                   \
        {"log-level", required_argument, 0, SH_CLI_LOG_LEVEL}, {"quiet", no_argument, 0, SH_CLI_QUIET}

/* The common options' lines for a usage text (the options column at 21 characters). */
#define SH_CLI_USAGE                                                                              \
    "  --log-level LEVEL  what is logged on stderr: error, warning, info (default) or debug\n"   \
    "  --quiet            --log-level warning: errors and warnings only (no progress, no summary)\n" \
    "  -h, --help         this text\n"                                                           \
    "  --version          the version\n"

/* What a program calls itself in --version and in the hint of a usage error ("stillheart warp",
 * "stillheart-eval"). */
typedef struct {
    const char *command;
} sh_cli;

/* getopt_long's result ch for a common option or a refusal: --version prints and returns 0,
 * --log-level and --quiet set the level and return -1 (go on), '?' and ':' (and a bad
 * --log-level) print one line and return 2. */
int sh_cli_option(const sh_cli *cli, int ch, char **argv);

/* One line on stderr: "PROGRAM: message; try 'COMMAND --help'"; returns 2, the exit status of
 * a usage error. */
int sh_cli_usage_error(const sh_cli *cli, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* "error", "warning" (or "warn"), "info", "debug" sets the log level; 0 for anything else. */
int sh_cli_set_log_level(const char *text);

/* A boolean option's value: 1, yes, true, on / 0, no, false, off (case-insensitive); 0 when
 * text is none of them, else 1 with *out set. */
int sh_cli_parse_bool(const char *text, int *out);

/* A whole decimal number / a finite real in min..max for option (named in the refusal, one
 * line on stderr); 0 when text is not one, else 1 with *out set. */
int sh_cli_parse_int(const char *option, const char *text, int min, int max, int *out);
int sh_cli_parse_double(const char *option, const char *text, double min, double max, double *out);
/* A user for option (--owner): a user name, or a uid as a whole number; 0 when it is neither
 * (one line on stderr: "OPTION: no user 'TEXT'"), else 1 with *uid set. */
int sh_cli_parse_user(const char *option, const char *text, int64_t *uid);

/* A progress line on stderr, "label [#####     ] done/total  rate  ETA m:ss", redrawn at most
 * ten times a second; only when stderr is a terminal and the log level shows info (--quiet and
 * --log-level warning hide it). total <= 0: unknown, no bar and no ETA. */
typedef struct {
    int enabled, total;
    const char *label, *unit;
    double start, last;
} sh_cli_progress;
void sh_cli_progress_start(sh_cli_progress *p, const char *label, int total, const char *unit);
void sh_cli_progress_update(sh_cli_progress *p, int done);
void sh_cli_progress_end(sh_cli_progress *p);

/* JSON written as it goes: keys and commas placed by the writer. key is the member's name
 * inside an object and NULL inside an array or at the top. A non-finite number is null. Nesting
 * deeper than 16 is not supported. */
typedef struct {
    FILE *out;
    int depth;
    unsigned char count[16];
    char close[16];
} sh_cli_json;
void sh_cli_json_start(sh_cli_json *j, FILE *out);
void sh_cli_json_object(sh_cli_json *j, const char *key);
void sh_cli_json_array(sh_cli_json *j, const char *key);
void sh_cli_json_end(sh_cli_json *j); /* closes the innermost; at depth 0 a newline */
void sh_cli_json_string(sh_cli_json *j, const char *key, const char *value); /* NULL: null */
void sh_cli_json_number(sh_cli_json *j, const char *key, double value);
void sh_cli_json_int(sh_cli_json *j, const char *key, long long value);
void sh_cli_json_bool(sh_cli_json *j, const char *key, int value);
void sh_cli_json_null(sh_cli_json *j, const char *key);

#ifdef __cplusplus
}
#endif
#endif
