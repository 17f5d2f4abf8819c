#include "phantom_testutil.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef RENDER_BIN
#error "RENDER_BIN must name the stillheart-render binary of this build"
#endif

static char dirs[4][256];

const char *pt_render(int slot, const char *args)
{
    if (slot < 0 || slot > 3) return NULL;
    if (!dirs[slot][0]) {
        snprintf(dirs[slot], sizeof dirs[slot], "/tmp/phantom-test-XXXXXX");
        if (!mkdtemp(dirs[slot])) {
            dirs[slot][0] = '\0';
            return NULL;
        }
    }
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "'%s' %s --quiet --out '%s'", RENDER_BIN, args, dirs[slot]);
    return system(cmd) == 0 ? dirs[slot] : NULL;
}

void pt_cleanup(void)
{
    for (int i = 0; i < 4; i++)
        if (dirs[i][0]) {
            char cmd[1100];
            snprintf(cmd, sizeof cmd, "rm -rf '%s'", dirs[i]);
            if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dirs[i]);
            dirs[i][0] = '\0';
        }
}

int pt_same_file(const char *a, const char *b)
{
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    int same = fa && fb;
    static char ba[1 << 16], bb[1 << 16];
    while (same) {
        size_t na = fread(ba, 1, sizeof ba, fa), nb = fread(bb, 1, sizeof bb, fb);
        if (na != nb || memcmp(ba, bb, na) != 0) same = 0;
        if (na == 0) break;
    }
    if (fa) fclose(fa);
    if (fb) fclose(fb);
    return same;
}
