/* libFuzzer: arbitrary bytes as a points CSV. Anything accepted must be sorted, indexed
 * consistently, free of duplicates and non-finite values (x, y are NaN exactly in a
 * `frame,id,X,Y,Z` file), and must write and parse back to exactly the same rows. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/points.h"

static void check(int ok)
{
    if (!ok) abort();
}

static int same_double(double a, double b)
{
    return (isnan(a) && isnan(b)) || memcmp(&a, &b, sizeof a) == 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    sh_points p;
    if (sh_points_parse((const char *)data, size, "fuzz.csv", &p) != SH_OK) {
        check(strncmp(sh_error_message(), "fuzz.csv:", 9) == 0);
        return 0;
    }
    check(p.count >= 0 && p.max_frame >= -1);
    /* accepted: nothing but blank space after the last newline (a cut file is refused) */
    size_t tail = size;
    while (tail && data[tail - 1] != '\n') {
        check(data[tail - 1] == ' ' || data[tail - 1] == '\t' || data[tail - 1] == '\r');
        tail--;
    }
    check(p.frame_start[0] == 0 && p.frame_start[p.max_frame + 1] == p.count);
    for (int i = 0; i < p.count; i++) {
        const sh_point *r = &p.rows[i];
        check(r->frame >= 0 && r->id >= 0);
        check(p.has_3d == SH_POINTS_XYZ_ONLY ? isnan(r->x) && isnan(r->y) : isfinite(r->x) && isfinite(r->y));
        check(p.has_3d ? isfinite(r->X) && isfinite(r->Y) && isfinite(r->Z) : isnan(r->X));
        if (i) {
            const sh_point *q = &p.rows[i - 1];
            check(q->frame < r->frame || (q->frame == r->frame && q->id < r->id));
        }
        int n;
        const sh_point *fr = sh_points_frame(&p, r->frame, &n);
        check(fr <= r && r < fr + n);
    }

    char *buf = NULL;
    size_t len = 0;
    FILE *mem = open_memstream(&buf, &len);
    check(mem && sh_points_write(mem, p.rows, p.count, p.has_3d) == SH_OK);
    fclose(mem);
    sh_points q;
    check(sh_points_parse(buf, len, "again", &q) == SH_OK);
    check(q.count == p.count && q.has_3d == p.has_3d && q.max_frame == p.max_frame);
    for (int i = 0; i < p.count; i++) {
        const sh_point *a = &p.rows[i], *b = &q.rows[i];
        check(a->frame == b->frame && a->id == b->id && same_double(a->x, b->x) &&
              same_double(a->y, b->y) && same_double(a->X, b->X) && same_double(a->Y, b->Y) &&
              same_double(a->Z, b->Z));
    }
    sh_points_destroy(&q);
    sh_points_destroy(&p);
    free(buf);
    return 0;
}
