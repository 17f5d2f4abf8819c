/* table2-plot: the Table II figure `make table2` writes beside its Markdown: e per method, one
 * bar per preset in each method's group, axes with numbers, drawn with the evaluator's 5x7 font
 * into a PNG (libpng through src/png, no plotting library). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval.h"
#include "stillheart/png.h"

#define PROG "table2-plot"
#define MAX_NAMES 16
#define NAME_LEN 32

static void usage(FILE *f)
{
    fprintf(f,
        "usage: " PROG " IN.csv OUT.png\n"
        "Draws e per method and preset as grouped bars. IN.csv: a header line, then\n"
        "preset,method,e lines (e a number >= 0; 'n/a' or empty: no bar); methods and presets\n"
        "in the order they first appear (at most %d each). Bars are drawn in matplotlib's tab10\n"
        "colours, one per preset (#1f77b4, #ff7f0e, #2ca02c, #d62728, then again), from the x\n"
        "axis up to e on a y axis from 0 to a round number above the largest e, e printed above\n"
        "each bar; white background, black axes and text.\n", MAX_NAMES);
}

typedef struct {
    char presets[MAX_NAMES][NAME_LEN], methods[MAX_NAMES][NAME_LEN];
    int np, nm;
    double e[MAX_NAMES][MAX_NAMES]; /* [method][preset], NAN: none */
} table;

static int index_of(char names[][NAME_LEN], int *n, const char *name)
{
    for (int i = 0; i < *n; i++)
        if (!strcmp(names[i], name)) return i;
    if (*n == MAX_NAMES) return -1;
    snprintf(names[*n], NAME_LEN, "%s", name);
    return (*n)++;
}

/* 0 on success; 1 with the reason printed. */
static int read_table(const char *path, table *t)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, PROG ": %s: %s\n", path, strerror(errno));
        return 1;
    }
    for (int m = 0; m < MAX_NAMES; m++)
        for (int p = 0; p < MAX_NAMES; p++) t->e[m][p] = NAN;
    char line[256];
    int no = 0, rc = 0;
    while (!rc && fgets(line, sizeof line, f)) {
        if (++no == 1) continue; /* the header */
        line[strcspn(line, "\r\n")] = '\0';
        char *preset = strtok(line, ","), *method = strtok(NULL, ","), *val = strtok(NULL, ",");
        if (!preset || !method || strlen(preset) >= NAME_LEN || strlen(method) >= NAME_LEN) {
            fprintf(stderr, PROG ": %s:%d: not preset,method,e\n", path, no);
            rc = 1;
            break;
        }
        int p = index_of(t->presets, &t->np, preset), m = index_of(t->methods, &t->nm, method);
        if (p < 0 || m < 0) {
            fprintf(stderr, PROG ": %s:%d: more than %d presets or methods\n", path, no, MAX_NAMES);
            rc = 1;
            break;
        }
        if (!val || !*val || !strcmp(val, "n/a")) continue;
        char *end;
        double e = strtod(val, &end);
        if (*end || !isfinite(e) || e < 0) {
            fprintf(stderr, PROG ": %s:%d: e '%s' is not a number >= 0\n", path, no, val);
            rc = 1;
        }
        t->e[m][p] = e;
    }
    fclose(f);
    if (!rc && (t->np == 0 || t->nm == 0)) {
        fprintf(stderr, PROG ": %s: no preset,method,e lines\n", path);
        rc = 1;
    }
    return rc;
}

/* The smallest 1, 2, 2.5 or 5 times a power of ten at or above v (v > 0). */
static double round_up(double v)
{
    double p = pow(10, floor(log10(v)));
    static const double steps[] = {1, 2, 2.5, 5, 10};
    for (int i = 0; i < 5; i++)
        if (steps[i] * p >= v * (1 - 1e-12)) return steps[i] * p;
    return 10 * p;
}

static const unsigned char tab10[4][3] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44}, {214, 39, 40}};
static const unsigned char black[3] = {0, 0, 0}, white[3] = {255, 255, 255};

/* The figure: title and legend on top, the y axis's numbers on the left, method names under
 * their groups. Sizes follow from the names, so every label fits. */
static sh_status draw(const table *t, sh_image *img)
{
    const int s = 2, line = (FONT_H + 4) * s;
    double top = 0;
    int name_w = 0;
    for (int m = 0; m < t->nm; m++) {
        int w = font_width(t->methods[m], s);
        if (w > name_w) name_w = w;
        for (int p = 0; p < t->np; p++)
            if (t->e[m][p] > top) top = t->e[m][p];
    }
    double ymax = top > 0 ? round_up(top) : 1, ystep = ymax / 5;
    int bar_w = 18 * s, group_w = t->np * bar_w + 6 * s;
    if (group_w < name_w + 4 * s) group_w = name_w + 4 * s;
    char buf[64];
    int left = 0;
    for (int k = 0; k <= 5; k++) {
        snprintf(buf, sizeof buf, "%g", ystep * k);
        if (font_width(buf, s) > left) left = font_width(buf, s);
    }
    left += 12 * s;
    int plot_h = 200 * s, top_margin = 3 * line, bottom = 2 * line;
    static const char title[] = "table ii: residual motion e per method (lower is better)";
    int W = left + t->nm * group_w + 8 * s, H = top_margin + plot_h + bottom;
    if (W < left + font_width(title, s) + 8 * s) W = left + font_width(title, s) + 8 * s;
    sh_status st = sh_image_create(img, SH_PIX_RGB24, W, H);
    if (st != SH_OK) return st;
    draw_box(img, 0, 0, W, H, white);
    draw_text(img, left, s * 2, title, s, black);
    int lx = left;
    for (int p = 0; p < t->np; p++) {
        draw_box(img, lx, line + 2 * s, lx + FONT_H * s, line + 2 * s + FONT_H * s, tab10[p % 4]);
        draw_text(img, lx + (FONT_H + 3) * s, line + 2 * s, t->presets[p], s, black);
        lx += (FONT_H + 3) * s + font_width(t->presets[p], s) + 12 * s;
    }
    int y0 = top_margin + plot_h; /* the x axis: e = 0 */
    for (int k = 0; k <= 5; k++) {
        int y = y0 - (int)lrint(plot_h * k / 5.0);
        snprintf(buf, sizeof buf, "%g", ystep * k);
        draw_text(img, left - 4 * s - font_width(buf, s), y - FONT_H * s / 2, buf, s, black);
        draw_box(img, left - 2 * s, y, left, y + 1, black);
    }
    for (int m = 0; m < t->nm; m++) {
        int gx = left + m * group_w, bx = gx + (group_w - t->np * bar_w) / 2;
        for (int p = 0; p < t->np; p++, bx += bar_w) {
            double e = t->e[m][p];
            if (isnan(e)) continue;
            int hgt = (int)lrint(e / ymax * plot_h);
            draw_box(img, bx + s, y0 - hgt, bx + bar_w - s, y0, tab10[p % 4]);
            snprintf(buf, sizeof buf, "%.3f", e);
            if (font_width(buf, 1) <= bar_w)
                draw_text(img, bx + (bar_w - font_width(buf, 1)) / 2, y0 - hgt - FONT_H - 2, buf, 1,
                          black);
        }
        draw_text(img, gx + (group_w - font_width(t->methods[m], s)) / 2, y0 + line / 2,
                  t->methods[m], s, black);
    }
    draw_box(img, left, top_margin - line / 2, left + 1, y0 + 1, black); /* y axis */
    draw_box(img, left, y0, W - 4 * s, y0 + 1, black);                   /* x axis */
    return SH_OK;
}

int main(int argc, char **argv)
{
    if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        usage(stdout);
        return 0;
    }
    if (argc != 3) {
        usage(stderr);
        return 2;
    }
    table t = {0};
    if (read_table(argv[1], &t)) return 1;
    sh_image img = {0};
    sh_status st = draw(&t, &img);
    if (st == SH_OK) st = sh_png_write(argv[2], &img, 1);
    sh_image_destroy(&img);
    if (st != SH_OK) {
        fprintf(stderr, PROG ": %s\n", sh_error_message());
        return 1;
    }
    return 0;
}
