/* stillheart-trackeval: the tracker on the phantom's truth with simulated detections; prints one
 * line of figures per run (docs/tracking.md's tables come from it). */
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"

static const sh_cli cli = {"stillheart-trackeval"};

static void usage(FILE *out)
{
    fprintf(out,
            "usage: stillheart-trackeval [--preset exvivo|invivo] [--cameras N] [--frames N] [--seed S]\n"
            "       [--noise PX] [--dropout P] [--partial PX] [--duplicates P] [--occlusions]\n"
            "       [--hide FRACTION --start S --duration S] [--spatial off|fuse] [--auto-ids]\n"
            "       [--harmonics H] [--resp R] [--q-base Q] [--q-harm Q] [--trace FILE.csv]\n"
            "       [--camera-motion pan|bump] [--camera-motion-at S] [--first-beat] [--first-beat-at S]\n"
            "       [--all-frames]\n"
            "The tracker on the phantom's truth with simulated detections: one run, its figures on\n"
            "standard output.\n"
            "  --camera-motion, --first-beat: the phantom's moved endoscope and sudden first beat\n"
            "  (stillheart-render --help); --all-frames: figures from frame 0, not from the lock\n"
            SH_CLI_USAGE);
}

enum {
    O_PRESET = 0x100, O_CAMERAS, O_FRAMES, O_SEED, O_NOISE, O_DROPOUT, O_PARTIAL, O_DUPLICATES, O_OCCLUSIONS,
    O_HIDE, O_START, O_DURATION, O_SPATIAL, O_AUTO_IDS, O_HARMONICS, O_RESP, O_Q_BASE, O_Q_HARM, O_TRACE,
    O_CAMERA_MOTION, O_CAMERA_MOTION_AT, O_FIRST_BEAT, O_FIRST_BEAT_AT, O_ALL_FRAMES
};

/* One option into c or o: 1, or 0 with the refusal printed. */
static int apply(int ch, const char *v, track_sim_config *c, sh_track_options *o)
{
    int n;
    switch (ch) {
    case O_PRESET:
        if (strcmp(v, "exvivo") && strcmp(v, "invivo")) { sh_cli_usage_error(&cli, "--preset: exvivo or invivo, not '%s'", v); return 0; }
        c->preset = v;
        return 1;
    case O_CAMERAS: return sh_cli_parse_int("--cameras", v, 1, SH_TRACK_MAX_CAMERAS, &c->cameras);
    case O_FRAMES: return sh_cli_parse_int("--frames", v, 1, 10000000, &c->frames);
    case O_SEED: if (!sh_cli_parse_int("--seed", v, 0, 2147483647, &n)) return 0;
                 c->seed = (unsigned long long)n; return 1;
    case O_NOISE: return sh_cli_parse_double("--noise", v, 0, 1000, &c->noise_px);
    case O_DROPOUT: return sh_cli_parse_double("--dropout", v, 0, 1, &c->dropout);
    case O_PARTIAL: return sh_cli_parse_double("--partial", v, 0, 1000, &c->partial_shift);
    case O_DUPLICATES: return sh_cli_parse_double("--duplicates", v, 0, 1, &c->duplicate_rate);
    case O_OCCLUSIONS: c->occlusions = 1; return 1;
    case O_HIDE: return sh_cli_parse_double("--hide", v, 0, 1, &c->hide_fraction);
    case O_START: return sh_cli_parse_double("--start", v, 0, 1e6, &c->hide_start);
    case O_DURATION: return sh_cli_parse_double("--duration", v, 0, 1e6, &c->hide_duration);
    case O_SPATIAL:
        if (strcmp(v, "off") && strcmp(v, "fuse")) { sh_cli_usage_error(&cli, "--spatial: off or fuse, not '%s'", v); return 0; }
        c->spatial = !strcmp(v, "off") ? SH_SPATIAL_OFF : SH_SPATIAL_FUSE;
        return 1;
    case O_AUTO_IDS: c->auto_ids = 1; return 1;
    case O_HARMONICS: return sh_cli_parse_int("--harmonics", v, 1, SH_TRACK_MAX_HEART_HARMONICS, &o->heart_harmonics);
    case O_RESP: return sh_cli_parse_int("--resp", v, 0, SH_TRACK_MAX_RESP_HARMONICS, &o->resp_harmonics);
    case O_Q_BASE: return sh_cli_parse_double("--q-base", v, 0, 1e9, &o->q_base);
    case O_Q_HARM: return sh_cli_parse_double("--q-harm", v, 0, 1e9, &o->q_harm);
    case O_TRACE: c->trace_path = v; return 1;
    case O_CAMERA_MOTION:
        if (strcmp(v, "pan") && strcmp(v, "bump")) { sh_cli_usage_error(&cli, "--camera-motion: pan or bump, not '%s'", v); return 0; }
        c->camera_motion = !strcmp(v, "pan") ? PHANTOM_CAM_PAN : PHANTOM_CAM_BUMP;
        return 1;
    case O_CAMERA_MOTION_AT: return sh_cli_parse_double("--camera-motion-at", v, 0, 1e6, &c->camera_motion_at);
    case O_FIRST_BEAT: c->first_beat = 1; return 1;
    case O_FIRST_BEAT_AT: return sh_cli_parse_double("--first-beat-at", v, 0, 1e6, &c->first_beat_at);
    case O_ALL_FRAMES: c->all_frames = 1; return 1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart-trackeval", SH_LOG_INFO);
    track_sim_config c;
    track_sim_default(&c);
    sh_track_options o;
    sh_track_options_default(&o);
    static const struct option options[] = {
        {"preset", 1, 0, O_PRESET}, {"cameras", 1, 0, O_CAMERAS}, {"frames", 1, 0, O_FRAMES},
        {"seed", 1, 0, O_SEED}, {"noise", 1, 0, O_NOISE}, {"dropout", 1, 0, O_DROPOUT},
        {"partial", 1, 0, O_PARTIAL}, {"duplicates", 1, 0, O_DUPLICATES}, {"occlusions", 0, 0, O_OCCLUSIONS},
        {"hide", 1, 0, O_HIDE}, {"start", 1, 0, O_START}, {"duration", 1, 0, O_DURATION},
        {"spatial", 1, 0, O_SPATIAL}, {"auto-ids", 0, 0, O_AUTO_IDS}, {"harmonics", 1, 0, O_HARMONICS},
        {"resp", 1, 0, O_RESP}, {"q-base", 1, 0, O_Q_BASE}, {"q-harm", 1, 0, O_Q_HARM},
        {"trace", 1, 0, O_TRACE}, {"camera-motion", 1, 0, O_CAMERA_MOTION},
        {"camera-motion-at", 1, 0, O_CAMERA_MOTION_AT}, {"first-beat", 0, 0, O_FIRST_BEAT},
        {"first-beat-at", 1, 0, O_FIRST_BEAT_AT}, {"all-frames", 0, 0, O_ALL_FRAMES},
        SH_CLI_OPTIONS, {0, 0, 0, 0}};
    int ch;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        if (ch == 'h') {
            usage(stdout);
            return 0;
        }
        if (ch >= O_PRESET && ch <= O_ALL_FRAMES) {
            if (!apply(ch, optarg, &c, &o)) return 2;
            continue;
        }
        int rc = sh_cli_option(&cli, ch, argv);
        if (rc >= 0) return rc;
    }
    if (optind != argc) return sh_cli_usage_error(&cli, "'%s': no operands", argv[optind]);
    track_sim_result r;
    sh_status st = track_sim_run(&c, &o, &r);
    if (st) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    printf("%s cams=%d hide=%.2f/%.2fs spatial=%s: lock@%d f_h=%.4f (true %.4f) f_r=%.4f (true %.4f)\n"
           "  visible: mean %.3f px max %.3f px (raw detections %.3f px)  3D mean %.3f mm max %.3f mm  n=%ld"
           "  found %ld/%ld\n"
           "  hidden:  mean %.3f px max %.3f px  3D mean %.3f mm  n=%ld lost=%ld\n"
           "  gated %ld misshapen %ld held %ld duplicates %ld unknown %ld inconsistent %ld corrupted-fed %ld false %ld decoy %ld\n",
           c.preset, c.cameras, c.hide_fraction, c.hide_duration, c.spatial ? "fuse" : "off",
           r.lock_frame, r.heart_hz, r.true_heart_hz, r.resp_hz, r.true_resp_hz, r.vis_mean_px,
           r.vis_max_px, r.raw_mean_px, r.vis_mean_mm, r.vis_max_mm, r.vis_count, r.found, r.visible, r.hid_mean_px,
           r.hid_max_px, r.hid_mean_mm, r.hid_count, r.hid_lost, r.stats.gated, r.stats.misshapen, r.stats.held, r.stats.duplicates,
           r.stats.unknown, r.stats.inconsistent, r.corrupted_fed, r.false_corr, r.decoy_reported);
    return 0;
}
