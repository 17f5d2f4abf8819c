/* Helpers shared by the phantom's tests: render a small sequence into a fresh temporary folder
 * with the build's own stillheart-render, and clean it up. */
#ifndef PHANTOM_TESTUTIL_H
#define PHANTOM_TESTUTIL_H

#ifdef __cplusplus
extern "C" {
#endif

/* Runs RENDER_BIN with `args` (a shell-quoted string) and --out <new temp dir> --quiet; returns
 * the folder (static storage, one per slot 0..3) or NULL when the renderer failed. */
const char *pt_render(int slot, const char *args);
/* Removes every folder pt_render made. */
void pt_cleanup(void);
/* 1 when the two files have the same bytes. */
int pt_same_file(const char *a, const char *b);

#ifdef __cplusplus
}
#endif
#endif
