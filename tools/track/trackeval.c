/* stillheart-trackeval: the tracker on the phantom's truth with simulated detections; prints one
 * line of figures per run (docs/tracking.md's tables come from it). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim.h"
#include "stillheart/log.h"

static void usage(void)
{
    fprintf(stderr,
            "usage: stillheart-trackeval [--preset exvivo|invivo] [--cameras N] [--frames N] [--seed S]\n"
            "       [--noise PX] [--dropout P] [--partial PX] [--duplicates P] [--occlusions]\n"
            "       [--hide FRACTION --start S --duration S] [--spatial off|fuse] [--auto-ids]\n"
            "       [--harmonics H] [--resp R] [--q-base Q] [--q-harm Q] [--trace FILE.csv]\n"
            "       [--camera-motion pan|bump] [--camera-motion-at S] [--first-beat] [--first-beat-at S]\n"
            "       [--all-frames]\n"
            "  --camera-motion, --first-beat: the phantom's moved endoscope and sudden first beat\n"
            "  (stillheart-render --help); --all-frames: figures from frame 0, not from the lock\n");
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart-trackeval", SH_LOG_INFO);
    track_sim_config c;
    track_sim_default(&c);
    sh_track_options o;
    sh_track_options_default(&o);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define ARG(name) (!strcmp(a, name) && v && ++i)
        if (ARG("--preset")) c.preset = v;
        else if (ARG("--cameras")) c.cameras = atoi(v);
        else if (ARG("--frames")) c.frames = atoi(v);
        else if (ARG("--seed")) c.seed = strtoull(v, NULL, 10);
        else if (ARG("--noise")) c.noise_px = atof(v);
        else if (ARG("--dropout")) c.dropout = atof(v);
        else if (ARG("--partial")) c.partial_shift = atof(v);
        else if (ARG("--duplicates")) c.duplicate_rate = atof(v);
        else if (!strcmp(a, "--occlusions")) c.occlusions = 1;
        else if (ARG("--hide")) c.hide_fraction = atof(v);
        else if (ARG("--start")) c.hide_start = atof(v);
        else if (ARG("--duration")) c.hide_duration = atof(v);
        else if (ARG("--spatial")) c.spatial = !strcmp(v, "off") ? SH_SPATIAL_OFF : SH_SPATIAL_FUSE;
        else if (!strcmp(a, "--auto-ids")) c.auto_ids = 1;
        else if (ARG("--harmonics")) o.heart_harmonics = atoi(v);
        else if (ARG("--resp")) o.resp_harmonics = atoi(v);
        else if (ARG("--q-base")) o.q_base = atof(v);
        else if (ARG("--q-harm")) o.q_harm = atof(v);
        else if (ARG("--trace")) c.trace_path = v;
        else if (ARG("--camera-motion") && (!strcmp(v, "pan") || !strcmp(v, "bump")))
            c.camera_motion = !strcmp(v, "pan") ? PHANTOM_CAM_PAN : PHANTOM_CAM_BUMP;
        else if (ARG("--camera-motion-at")) c.camera_motion_at = atof(v);
        else if (!strcmp(a, "--first-beat")) c.first_beat = 1;
        else if (ARG("--first-beat-at")) c.first_beat_at = atof(v);
        else if (!strcmp(a, "--all-frames")) c.all_frames = 1;
        else {
            usage();
            return 2;
        }
#undef ARG
    }
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
