/* libFuzzer: arbitrary bytes as the phantom's markers.csv. The reader lives with the phantom
 * tool (tools/phantom), outside libstillheart, so it is compiled in here. A refusal names the
 * file; accepted rows hold points 0..4, visibility 0/1 and no infinities, and every row can be
 * found again by its key. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../tools/phantom/markers_csv.c"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    phantom_csv csv;
    if (phantom_csv_parse((const char *)data, size, "fuzz.csv", &csv) != SH_OK) {
        check(strncmp(sh_error_message(), "fuzz.csv", 8) == 0);
        check(csv.rows == NULL && csv.count == 0);
        return 0;
    }
    for (int i = 0; i < csv.count; i++) {
        const phantom_csv_row *r = &csv.rows[i];
        check(r->point >= 0 && r->point <= 4 && (r->visible == 0 || r->visible == 1));
        check(r->frame >= 0 && r->camera >= 0 && r->id >= 0);
        check(!isinf(r->x) && !isinf(r->y) && !isinf(r->X) && !isinf(r->Y) && !isinf(r->Z));
        const phantom_csv_row *f = phantom_csv_find(&csv, r->frame, r->camera, r->id, r->point);
        check(f != NULL && f->frame == r->frame && f->camera == r->camera && f->id == r->id &&
              f->point == r->point);
    }
    phantom_csv_free(&csv);
    return 0;
}
