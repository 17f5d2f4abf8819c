/* The points CSV: layout tolerance, every refusal with its exact "FILE:LINE: reason", sorting,
 * the frame index, and exact write/read round trips. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <unistd.h>

#include "stillheart/points.h"

static sh_status parse(const char *text, sh_points *p)
{
    return sh_points_parse(text, strlen(text), "pts.csv", p);
}

static void test_layout_tolerance(void **state)
{
    (void)state;
    /* BOM, CRLF, blank lines (one with spaces), spaces and tabs around fields, rows out of
     * order. */
    const char *text = "\xEF\xBB\xBF frame , id,x,y\r\n"
                       "\r\n"
                       "2,5, 10.5 ,\t-3\r\n"
                       "   \n"
                       "0,1,1e2,0.25\n"
                       "2,0,+7,8.125\n"
                       "0,0,-1.5,2\n";
    sh_points p;
    assert_int_equal(parse(text, &p), SH_OK);
    assert_int_equal(p.count, 4);
    assert_int_equal(p.has_3d, 0);
    assert_int_equal(p.max_frame, 2);
    const int want_frame[] = {0, 0, 2, 2}, want_id[] = {0, 1, 0, 5};
    const double want_x[] = {-1.5, 100.0, 7.0, 10.5}, want_y[] = {2.0, 0.25, 8.125, -3.0};
    for (int i = 0; i < 4; i++) {
        assert_int_equal(p.rows[i].frame, want_frame[i]);
        assert_int_equal(p.rows[i].id, want_id[i]);
        assert_true(p.rows[i].x == want_x[i]);
        assert_true(p.rows[i].y == want_y[i]);
        assert_true(isnan(p.rows[i].X) && isnan(p.rows[i].Y) && isnan(p.rows[i].Z));
    }
    /* frame_start: frame 0 -> [0,2), frame 1 -> [2,2), frame 2 -> [2,4) */
    assert_int_equal(p.frame_start[0], 0);
    assert_int_equal(p.frame_start[1], 2);
    assert_int_equal(p.frame_start[2], 2);
    assert_int_equal(p.frame_start[3], 4);
    int n;
    const sh_point *rows = sh_points_frame(&p, 2, &n);
    assert_int_equal(n, 2);
    assert_int_equal(rows[1].id, 5);
    sh_points_frame(&p, 1, &n);
    assert_int_equal(n, 0);
    sh_points_frame(&p, 3, &n);
    assert_int_equal(n, 0);
    sh_points_frame(&p, -1, &n);
    assert_int_equal(n, 0);
    sh_points_destroy(&p);
}

static void test_3d_and_header_only(void **state)
{
    (void)state;
    sh_points p;
    assert_int_equal(parse("frame,id,x,y,X,Y,Z\n1,3,1,2,-4.5,5,6e-3\n", &p), SH_OK);
    assert_int_equal(p.has_3d, 1);
    assert_int_equal(p.count, 1);
    assert_true(p.rows[0].X == -4.5 && p.rows[0].Y == 5.0 && p.rows[0].Z == 6e-3);
    assert_int_equal(p.frame_start[0], 0);
    assert_int_equal(p.frame_start[1], 0);
    assert_int_equal(p.frame_start[2], 1);
    sh_points_destroy(&p);

    /* 3D markers from another tracker: no image positions, which 2D users refuse */
    assert_int_equal(parse("frame , id,X,Y,Z\r\n2,3,-4.5,5,6e-3\r\n0,3,1,2,3\r\n", &p), SH_OK);
    assert_int_equal(p.has_3d, SH_POINTS_XYZ_ONLY);
    assert_int_equal(p.count, 2);
    assert_true(p.rows[1].frame == 2 && p.rows[1].X == -4.5 && p.rows[1].Y == 5.0 && p.rows[1].Z == 6e-3);
    assert_true(p.rows[0].frame == 0 && p.rows[0].X == 1 && p.rows[0].Y == 2 && p.rows[0].Z == 3);
    assert_true(isnan(p.rows[0].x) && isnan(p.rows[0].y) && isnan(p.rows[1].x));
    assert_int_equal(sh_points_need_2d(&p, "xyz.csv"), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "xyz.csv"));
    assert_non_null(strstr(sh_error_message(), "x,y"));
    sh_points_destroy(&p);

    assert_int_equal(parse("frame,id,x,y\n\n", &p), SH_OK);
    assert_int_equal(sh_points_need_2d(&p, "xy.csv"), SH_OK);
    assert_int_equal(p.count, 0);
    assert_int_equal(p.max_frame, -1);
    int n = 7;
    sh_points_frame(&p, 0, &n);
    assert_int_equal(n, 0);
    sh_points_destroy(&p);
}

static void expect_error(const char *text, const char *message)
{
    sh_points p;
    assert_int_equal(parse(text, &p), SH_EFORMAT);
    assert_string_equal(sh_error_message(), message);
    assert_null(p.rows);
    sh_points_destroy(&p);
}

static void test_refusals_name_the_line(void **state)
{
    (void)state;
    const char *hdr_msg = "bad header, expected 'frame,id,x,y', 'frame,id,x,y,X,Y,Z' or 'frame,id,X,Y,Z'";
    char want[200];
    snprintf(want, sizeof want, "pts.csv:1: %s", hdr_msg);
    expect_error("frame,id,x\n0,0,1\n", want);
    expect_error("frame,id,y,x\n", want);
    expect_error("Frame,id,x,y\n", want);
    expect_error("frame,id,x,y,X,Y\n", want);
    expect_error("frame,id,X,Y\n", want);
    expect_error("frame,id,X,Y,Z,x,y\n", want);
    expect_error("frame,id,Z,Y,X\n", want);
    snprintf(want, sizeof want, "pts.csv:3: %s", hdr_msg);
    expect_error("\r\n\r\n0,0,1,2\r\n", want);
    expect_error("", "pts.csv:1: no header, expected 'frame,id,x,y'");
    expect_error("\n \n", "pts.csv:2: no header, expected 'frame,id,x,y'");

    expect_error("frame,id,x,y\r\n0,0,1,2\r\n\r\n0,1,1\r\n",
                 "pts.csv:4: 3 columns, the header has 4");
    expect_error("frame,id,x,y\n0,0,1,2,3\n", "pts.csv:2: 5 columns, the header has 4");
    expect_error("frame,id,x,y,X,Y,Z\n0,0,1,2\n", "pts.csv:2: 4 columns, the header has 7");
    expect_error("frame,id,x,y\n0,0,1,2,3,4,5,6,7,8\n",
                 "pts.csv:2: more than 7 columns, the header has 4");
    expect_error("frame,id,x,y\n0,0,1,2\n1,0,abc,2\n", "pts.csv:3: x 'abc' is not a number");
    expect_error("frame,id,x,y\n0,0,1,\n", "pts.csv:2: y '' is not a number");
    expect_error("frame,id,x,y\n0,0,1,2 3\n", "pts.csv:2: y '2 3' is not a number");
    expect_error("frame,id,x,y\n0.5,0,1,2\n", "pts.csv:2: frame '0.5' is not an integer");
    expect_error("frame,id,x,y\nx,0,1,2\n", "pts.csv:2: frame 'x' is not an integer");
    expect_error("frame,id,x,y\n-1,0,1,2\n", "pts.csv:2: negative frame '-1'");
    expect_error("frame,id,x,y\n0,-3,1,2\n", "pts.csv:2: negative id '-3'");
    expect_error("frame,id,x,y\n0,99999999999,1,2\n",
                 "pts.csv:2: id '99999999999' out of range (max 2147483647)");
    expect_error("frame,id,x,y\n20000000,0,1,2\n",
                 "pts.csv:2: frame '20000000' out of range (max 10000000)");
    expect_error("frame,id,x,y\n0,0,nan,2\n", "pts.csv:2: x 'nan' is not finite");
    expect_error("frame,id,x,y\n0,0,1,-inf\n", "pts.csv:2: y '-inf' is not finite");
    expect_error("frame,id,x,y\n0,0,1,1e999\n", "pts.csv:2: y '1e999' is not finite");
    expect_error("frame,id,x,y,X,Y,Z\n0,0,1,2,3,4,NaN\n", "pts.csv:2: Z 'NaN' is not finite");
    expect_error("frame,id,X,Y,Z\n0,0,1,2,3,4,5\n", "pts.csv:2: 7 columns, the header has 5");
    expect_error("frame,id,X,Y,Z\n0,0,1,inf,3\n", "pts.csv:2: Y 'inf' is not finite");
    expect_error("frame,id,X,Y,Z\n0,0,1,2,z\n", "pts.csv:2: Z 'z' is not a number");
    expect_error("frame,id,x,y\r\n3,1,1,2\r\n0,0,1,2\r\n3,1,5,6\r\n",
                 "pts.csv:4: duplicate marker: frame 3 id 1 (first at line 2)");
    /* numbers are whole fields: what strtod stops short of is refused, not dropped */
    expect_error("frame,id,x,y\n0,0,2.5x,1\n", "pts.csv:2: x '2.5x' is not a number");
    expect_error("frame,id,x,y\n0,0,1e,1\n", "pts.csv:2: x '1e' is not a number");
    expect_error("frame,id,x,y\n0,0,1,-\n", "pts.csv:2: y '-' is not a number");
    expect_error("frame,id,x,y\n0,0,.,1\n", "pts.csv:2: x '.' is not a number");
    expect_error("frame,id,x,y\n0,0,1,2;\n", "pts.csv:2: y '2;' is not a number");
    const char nul[] = "frame,id,x,y\n0,0,1\0,2\n";
    sh_points p;
    assert_int_equal(sh_points_parse(nul, sizeof nul - 1, "pts.csv", &p), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "pts.csv:2: x"));
}

/* A file cut anywhere before its last newline is refused naming the last line: the y =
 * 24.31 cut to "2" parses as a number, so only the missing newline gives the cut away. */
static void test_cut_file_refused(void **state)
{
    (void)state;
    const char *full = "frame,id,x,y\n0,0,10.5,20.25\n4,7,130.5,24.31\n";
    size_t n = strlen(full);
    const size_t row2 = strlen("frame,id,x,y\n0,0,10.5,20.25\n");
    for (size_t cut = 1; cut < n; cut++) {
        sh_points p;
        sh_status st = sh_points_parse(full, cut, "pts.csv", &p);
        if (full[cut - 1] == '\n') {
            /* cut at a line's end: a shorter file, not a damaged one */
            assert_int_equal(st, SH_OK);
            assert_int_equal(p.count, cut == n ? 2 : cut == row2 ? 1 : 0);
            sh_points_destroy(&p);
            continue;
        }
        assert_int_equal(st, SH_EFORMAT);
        int line = cut < strlen("frame,id,x,y\n") ? 1 : cut < row2 ? 2 : 3;
        char want[160];
        snprintf(want, sizeof want, "pts.csv:%d: the last line does not end in a newline (is the file cut?)", line);
        assert_string_equal(sh_error_message(), want);
        assert_null(p.rows);
    }
    sh_points p;
    assert_int_equal(sh_points_parse(full, n, "pts.csv", &p), SH_OK);
    assert_true(p.rows[1].y == 24.31);
    sh_points_destroy(&p);
    /* trailing blank space after the last newline is layout, not a cut */
    assert_int_equal(parse("frame,id,x,y\n0,0,1,2\n  \t", &p), SH_OK);
    assert_int_equal(p.count, 1);
    sh_points_destroy(&p);
}

static void test_write_read_round_trip(void **state)
{
    (void)state;
    const sh_point rows[] = {
        {0, 0, 0.1, 1.0 / 3.0, -2.5, 1e-12, 12345.678901234567},
        {0, 7, 32766.999999999, -0.0, 1e300, -7, 0},
        {4, 2, 5, 6, 7, 8, 9},
    };
    for (int has_3d = 0; has_3d <= SH_POINTS_XYZ_ONLY; has_3d++) {
        char *buf = NULL;
        size_t len = 0;
        FILE *mem = open_memstream(&buf, &len);
        assert_int_equal(sh_points_write(mem, rows, 3, has_3d), SH_OK);
        fclose(mem);
        const char *heads[] = {"frame,id,x,y\n0,0,0.1,0.333333333333333",
                               "frame,id,x,y,X,Y,Z\n0,0,0.1,0.333333333333333", "frame,id,X,Y,Z\n0,0,-2.5,1e-12,"};
        const char *head = heads[has_3d];
        assert_true(strncmp(buf, head, strlen(head)) == 0);
        sh_points p;
        assert_int_equal(sh_points_parse(buf, len, "mem", &p), SH_OK);
        assert_int_equal(p.count, 3);
        assert_int_equal(p.has_3d, has_3d);
        for (int i = 0; i < 3; i++) {
            assert_int_equal(p.rows[i].frame, rows[i].frame);
            assert_int_equal(p.rows[i].id, rows[i].id);
            if (has_3d == SH_POINTS_XYZ_ONLY) {
                assert_true(isnan(p.rows[i].x) && isnan(p.rows[i].y));
            } else {
                assert_memory_equal(&p.rows[i].x, &rows[i].x, sizeof(double)); /* bit-exact */
                assert_memory_equal(&p.rows[i].y, &rows[i].y, sizeof(double));
            }
            if (has_3d) {
                assert_memory_equal(&p.rows[i].X, &rows[i].X, sizeof(double));
                assert_memory_equal(&p.rows[i].Y, &rows[i].Y, sizeof(double));
                assert_memory_equal(&p.rows[i].Z, &rows[i].Z, sizeof(double));
            }
        }
        sh_points_destroy(&p);
        free(buf);
    }
    /* non-finite values would make an unreadable file: refused before anything is written */
    sh_point bad = {0, 0, NAN, 1, 0, 0, 0};
    FILE *devnull = fopen("/dev/null", "w");
    assert_int_equal(sh_points_write(devnull, &bad, 1, 0), SH_EINVAL);
    fclose(devnull);
    if (access("/dev/full", W_OK) == 0) {
        FILE *full = fopen("/dev/full", "w");
        assert_int_equal(sh_points_write(full, rows, 3, 1), SH_EIO);
        fclose(full);
    }
}

static void test_read_file(void **state)
{
    (void)state;
    char path[] = "/tmp/sh_test_points_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    const char text[] = "frame,id,x,y\n1,0,1,2\n1,x,1,2\n";
    assert_int_equal(write(fd, text, sizeof text - 1), (ssize_t)(sizeof text - 1));
    close(fd);
    sh_points p;
    assert_int_equal(sh_points_read(path, &p), SH_EFORMAT);
    char want[200];
    snprintf(want, sizeof want, "%s:3: id 'x' is not an integer", path);
    assert_string_equal(sh_error_message(), want);
    /* y = 2 cut from "2.5": refused with the file and line */
    fd = open(path, O_WRONLY | O_TRUNC);
    assert_int_equal(write(fd, "frame,id,x,y\n1,0,1,2", 20), 20);
    close(fd);
    assert_int_equal(sh_points_read(path, &p), SH_EFORMAT);
    snprintf(want, sizeof want, "%s:2: the last line does not end in a newline (is the file cut?)", path);
    assert_string_equal(sh_error_message(), want);
    fd = open(path, O_WRONLY | O_TRUNC);
    assert_int_equal(write(fd, text, 21), 21);
    close(fd);
    assert_int_equal(sh_points_read(path, &p), SH_OK);
    assert_int_equal(p.count, 1);
    assert_int_equal(p.max_frame, 1);
    sh_points_destroy(&p);
    unlink(path);

    assert_int_equal(sh_points_read("/nonexistent-dir/p.csv", &p), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent-dir/p.csv"));
}

/* The ids two frames share, with the current frame's positions, worked by hand. */
static void test_match(void **state)
{
    (void)state;
    const sh_point ref[] = {{.id = 1}, {.id = 3, .x = 30, .y = 31}, {.id = 4}, {.id = 9, .x = 90, .y = 91}};
    const sh_point cur[] = {{.id = 0, .x = 5, .y = 6}, {.id = 3, .x = 7, .y = 8},
                            {.id = 9, .x = 1.5, .y = 2.5}, {.id = 12, .x = 3, .y = 4}};
    int ids[4];
    double xy[8];
    double rxy[8];
    assert_int_equal(sh_points_match(ref, 4, cur, 4, ids, NULL, xy), 2);
    assert_int_equal(ids[0], 3);
    assert_int_equal(ids[1], 9);
    assert_true(xy[0] == 7 && xy[1] == 8 && xy[2] == 1.5 && xy[3] == 2.5);
    /* the reference's positions of the same ids, when asked */
    assert_int_equal(sh_points_match(ref, 4, cur, 4, ids, rxy, xy), 2);
    assert_true(rxy[0] == 30 && rxy[1] == 31 && rxy[2] == 90 && rxy[3] == 91);
    assert_int_equal(sh_points_match(ref, 4, cur, 0, ids, NULL, xy), 0);
}

/* The ids two frames share with X, Y, Z in both, worked by hand: a row without them on either
 * side is no shared 3D point. */
static void test_match_xyz(void **state)
{
    (void)state;
    const sh_point ref[] = {{.id = 1, .X = 1, .Y = 1, .Z = 1},
                            {.id = 3, .X = 3, .Y = 3, .Z = 3},
                            {.id = 4, .X = NAN, .Y = 4, .Z = 4},
                            {.id = 9, .X = 9, .Y = 9, .Z = 9}};
    const sh_point cur[] = {{.id = 1, .X = 10, .Y = 11, .Z = NAN},
                            {.id = 3, .X = 30, .Y = 31, .Z = 32},
                            {.id = 4, .X = 40, .Y = 41, .Z = 42},
                            {.id = 9, .X = 90, .Y = 91, .Z = 92},
                            {.id = 12, .X = 1, .Y = 2, .Z = 3}};
    int ids[5];
    double xyz[15];
    assert_int_equal(sh_points_match_xyz(ref, 4, cur, 5, ids, xyz), 2);
    assert_int_equal(ids[0], 3);
    assert_int_equal(ids[1], 9);
    assert_true(xyz[0] == 30 && xyz[1] == 31 && xyz[2] == 32 && xyz[3] == 90 && xyz[4] == 91 && xyz[5] == 92);
    assert_int_equal(sh_points_match_xyz(ref, 4, cur, 0, ids, xyz), 0);
    /* every reference row from id 4 on kept (4 has no X in the reference: not a 3D point), the
     * frame's positions where it has them, the reference's where not */
    unsigned char use[5];
    int used = -1;
    const sh_point cur2[] = {{.id = 1, .X = 10, .Y = 11, .Z = 12}, {.id = 3, .X = 30, .Y = 31, .Z = 32}};
    assert_int_equal(sh_points_match_xyz_keep(ref, 4, cur2, 2, 4, ids, xyz, use, &used), 3);
    assert_int_equal(used, 2);
    assert_true(ids[0] == 1 && ids[1] == 3 && ids[2] == 9);
    assert_true(use[0] == 1 && use[1] == 1 && use[2] == 0);
    assert_true(xyz[0] == 10 && xyz[3] == 30 && xyz[6] == 9 && xyz[7] == 9 && xyz[8] == 9);
    assert_int_equal(sh_points_match_xyz_keep(ref, 4, cur, 5, 4, ids, xyz, use, &used), 2);
    assert_int_equal(used, 2);
    assert_true(ids[0] == 3 && ids[1] == 9 && use[0] == 1 && use[1] == 1 && xyz[3] == 90);
}

/* Landmark rows (ids from a limit on) dropped: every other row kept in order, every frame still
 * there, a frame left with no row answering none. */
static void test_drop_ids(void **state)
{
    (void)state;
    const char *text = "frame,id,x,y\n0,1,1,1\n0,1000000,2,2\n0,1000003,3,3\n1,1000001,4,4\n2,2,5,5\n2,1000002,6,6\n";
    sh_points p;
    assert_int_equal(sh_points_parse(text, strlen(text), "t.csv", &p), SH_OK);
    assert_int_equal(sh_points_drop_ids(&p, 1000000), 4);
    assert_int_equal(p.count, 2);
    assert_int_equal(p.max_frame, 2);
    int n;
    const sh_point *r = sh_points_frame(&p, 0, &n);
    assert_int_equal(n, 1);
    assert_int_equal(r[0].id, 1);
    sh_points_frame(&p, 1, &n);
    assert_int_equal(n, 0);
    r = sh_points_frame(&p, 2, &n);
    assert_int_equal(n, 1);
    assert_int_equal(r[0].id, 2);
    assert_true(r[0].x == 5);
    assert_int_equal(sh_points_drop_ids(&p, 1000000), 0);
    sh_points_destroy(&p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_layout_tolerance),
        cmocka_unit_test(test_3d_and_header_only),
        cmocka_unit_test(test_refusals_name_the_line),
        cmocka_unit_test(test_cut_file_refused),
        cmocka_unit_test(test_write_read_round_trip),
        cmocka_unit_test(test_read_file),
        cmocka_unit_test(test_match),
        cmocka_unit_test(test_match_xyz),
        cmocka_unit_test(test_drop_ids),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
