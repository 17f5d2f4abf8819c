/* Tracker evaluation on the phantom's analytic truth: detections simulated from the model
 * (centres and corners with Gaussian noise, random dropouts, partial occlusions giving a wrong
 * quad, duplicated ids, the decoy), forced occlusions of chosen markers, and the tracker's
 * estimates compared with the truth. Used by test_track_phantom and stillheart-trackeval. */
#ifndef STILLHEART_TRACK_SIM_H
#define STILLHEART_TRACK_SIM_H

#include "phantom.h"
#include "stillheart/track.h"

typedef struct {
    const char *preset;     /* exvivo / invivo */
    int cameras;            /* 1: 2D tracking in camera 0; 2-3: 3D */
    int frames;
    uint64_t seed;
    int occlusions;         /* the phantom's shaft, blobs and decoy */
    double noise_px;        /* detection noise per coordinate (0.2) */
    double dropout;         /* probability a visible tag is not detected */
    double partial_shift;   /* a tag partly hidden is detected in 30% of the frames
                             * (libapriltag mostly fails on a broken border) with its hidden
                             * corners, or one side, off by this (px) in a random direction and
                             * the centre where libapriltag puts it (the diagonals' crossing:
                             * about half of this off); 0: never detected */
    double duplicate_rate;  /* probability per frame and camera of a duplicated id far away */
    double hide_fraction;   /* forced occlusion: this fraction of the markers ... */
    double hide_start, hide_duration; /* ... from hide_start for hide_duration seconds */
    int auto_ids;           /* tracker learns ids (no whitelist) */
    sh_spatial_mode spatial;
    const char *trace_path; /* per frame CSV of hidden markers' errors (NULL: none) */
    int camera_motion;      /* the phantom's moved endoscope: 0 none, 1 pan, 2 bump (phantom.h) */
    double camera_motion_at; /* seconds; <= 0: 40 % into the sequence */
    int first_beat;         /* 1: the heart rests, then a first contraction 4x faster */
    double first_beat_at;   /* seconds of rest; <= 0: 0.5 s */
    int all_frames;         /* 1: errors and found/visible counted from frame 0, not only once the
                             * rates lock (to measure tracking before the lock) */
    const double *distortion; /* k1 k2 p1 p2 k3 of every camera (NULL: none) */
    /* the tracker given a wrong calibration: cameras swap_a and swap_b swapped (equal: not), and
     * camera 1's translation scaled by t1_scale (0: 1) */
    int swap_a, swap_b;
    double t1_scale;
} track_sim_config;

typedef struct {
    /* errors of every confirmed, not lost estimate after the rates locked (every frame with
     * all_frames), camera 0 pixels */
    double vis_mean_px, vis_max_px;   /* frames where the marker was detected (measured) */
    double vis_mean_mm, vis_max_mm;   /* 3D: the same in world units */
    long vis_count;
    double hid_mean_px, hid_max_px;   /* forced-hidden markers during the hiding */
    double hid_mean_mm;
    long hid_count;
    long hid_lost;                    /* forced-hidden estimates reported lost */
    double raw_mean_px;               /* the simulated detections' own error (centre) */
    long false_corr;                  /* measured estimates off the truth by > 1.5 px (3D: 1 mm) after a
                                       * corrupted detection, plus reported decoys */
    long decoy_reported;
    long corrupted_fed;               /* corrupted detections given to the tracker */
    long visible;                     /* (marker, frame) pairs, over the same frames as the
                                       * errors, where the marker's centre is visible in camera 0
                                       * (truth) and not forcibly hidden */
    long found;                       /* ... of which the tracker reported the marker confirmed
                                       * and MEASURED: found / visible is the detection rate */
    int lock_frame;                   /* first frame with rates locked (-1 never) */
    double heart_hz, resp_hz, true_heart_hz, true_resp_hz;
    sh_track_stats stats;
    sh_track_calibration calibration; /* 3D: the tracker's calibration check at the end */
} track_sim_result;

void track_sim_default(track_sim_config *c);
sh_status track_sim_run(const track_sim_config *c, const sh_track_options *opts, track_sim_result *r);

#endif
