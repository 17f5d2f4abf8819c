/* For the tests that run our programs: a shell command, its exit status and what it printed. */
#ifndef STILLHEART_TEST_SHELL_H
#define STILLHEART_TEST_SHELL_H

#define TEST_CMD_MAX 4096
#define TEST_OUT_MAX 16384

extern char test_cmd[TEST_CMD_MAX]; /* the last command given to test_run */
extern char test_out[TEST_OUT_MAX]; /* its stdout and stderr, NUL-terminated (cut at the size) */

/* Runs the printf-formatted command under /bin/sh with stderr joined to stdout; returns its exit
 * status (-1 when it did not exit). The test fails at once when the shell cannot be started. */
int test_run(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* The number after the first "key": in a JSON text (our programs' --json output), NaN when the key
 * is absent or its value is not a number (null). */
double test_json_num(const char *json, const char *key);

#endif
