/* tests/unit/shell.h: linked into every unit test and into the tool tests that run programs. */
#include "shell.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include <cmocka.h>

char test_cmd[TEST_CMD_MAX];
char test_out[TEST_OUT_MAX];

int test_run(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(test_cmd, sizeof test_cmd, fmt, ap);
    va_end(ap);
    char full[TEST_CMD_MAX + 8];
    snprintf(full, sizeof full, "%s 2>&1", test_cmd);
    FILE *p = popen(full, "r");
    assert_non_null(p);
    size_t n = fread(test_out, 1, sizeof test_out - 1, p);
    test_out[n] = 0;
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

double test_json_num(const char *json, const char *key)
{
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\": ", key);
    const char *p = strstr(json, pat);
    if (!p) return NAN;
    char *end;
    double v = strtod(p + strlen(pat), &end);
    return end == p + strlen(pat) ? NAN : v;
}
