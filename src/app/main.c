/* stillheart: one command, several jobs (subcommands). */
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "stillheart/log.h"

static const struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} commands[] = {
    {"warp", cmd_warp, "stabilize a Y4M video from a points file (paper Algorithm 1)"},
    {"detect", cmd_detect, "print every AprilTag detection of a video or image as CSV"},
    {"warp3d", cmd_warp3d, "3D stabilization, stereo and virtual views, PLY export (paper Algorithm 2)"},
    {"track", cmd_track, "track the markers of a video (Kalman, 2D or 3D) into a points file"},
    {"record", cmd_record, "record cameras as delivered (frames, timestamps, sets); recording to Y4M"},
    {"run", cmd_run, "the daemon: live stabilization into the shared-memory display buffer"},
    {"ctl", cmd_ctl, "ask the running daemon for its status or a new reference (control socket)"},
};

static void usage(FILE *out)
{
    fprintf(out, "usage: stillheart COMMAND [OPTIONS]\n\n"
                 "stillheart stabilizes video of a beating heart onto a reference frame.\n\n"
                 "commands:\n");
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(out, "  %-8s %s\n", commands[i].name, commands[i].summary);
    fprintf(out, "\noptions:\n"
                 "  -h, --help   this text\n"
                 "  --version    the version\n\n"
                 "'stillheart COMMAND --help' documents each command.\n");
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart", SH_LOG_INFO);
    if (argc < 2) {
        sh_log_error("no command given; try 'stillheart --help'");
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(argv[1], "--version")) {
        printf("stillheart %s\n", SH_VERSION);
        return 0;
    }
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(argv[1], commands[i].name)) return commands[i].run(argc - 1, argv + 1);
    if (argv[1][0] == '-') sh_log_error("unknown option '%s'; try 'stillheart --help'", argv[1]);
    else sh_log_error("unknown command '%s'; try 'stillheart --help'", argv[1]);
    return 2;
}
