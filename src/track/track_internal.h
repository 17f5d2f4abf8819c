/* Private to src/track: the tracker's state and the pieces its files share
 * (track.c: create and the per-frame steps; gate.c: one marker's update and the predictions it
 * is gated against; quad.c: the shape test of a detection; filter.c: the Kalman filter of one
 * coordinate; rates.c: the heartbeat and respiration rates from all markers' recent tracks;
 * consensus.c: the detections judged against each other; calcheck.c: whether the calibration fits
 * what the cameras see). */
#ifndef STILLHEART_TRACK_INTERNAL_H
#define STILLHEART_TRACK_INTERNAL_H

#include "stillheart/camera.h"
#include "stillheart/track.h"

#define PI 3.14159265358979323846
#define HMAX SH_TRACK_MAX_HEART_HARMONICS
#define RMAX SH_TRACK_MAX_RESP_HARMONICS
#define NS (2 + 2 * (HMAX + RMAX)) /* state: p, v, heart pairs, resp pairs */
#define NC (2 + 2 * (HMAX + RMAX)) /* LS fit: mean, trend, heart pairs, resp pairs */
#define MAXM SH_TRACK_MAX_MARKERS
#define MAXC SH_TRACK_MAX_CAMERAS
#define RATE_SERIES 16            /* series used for the periodogram (largest variance) */
#define RATE_FFT_MIN 128          /* 4 x the 32 samples a rate estimate needs at least */
#define RATE_FFT_MAX (4 * SH_TRACK_HISTORY)
#define RATE_FFT_SIZES 5          /* 128 .. 2048 */
#define RATE_BASIS_TABLES 4
#define CAL_WINDOW 256            /* calcheck.c: markers seen by every camera, the last so many */       /* heart only, trend only, respiration only, heart and respiration */

typedef struct {
    double x[NS];
    double P[NS * NS];
} axis_filter;

typedef struct {
    int id;
    int init;              /* filter initialised */
    int confirmed;
    int lost;
    int age, seen;
    int measured;          /* accepted detection this frame */
    int spatial;           /* reported estimate used neighbours this frame */
    axis_filter f[3];
    double extent[MAXC];   /* apparent half-size (centre to farthest corner), px; 0 unknown */
    double half[MAXC][2];  /* half-width and half-height of its last accepted quad's bounding box */
    int last_frame;        /* frame of the last accepted detection */
    int rejects;           /* consecutive frames with this id's detections gated away */
    double rej_sum[2], rej_ss; /* their offsets from the prediction (px): sum, sum of squares */
    /* shape test (quad.c): per camera the last accepted quad (corners minus their mean) */
    double quad[MAXC][4][2];
    int quad_ok[MAXC], quad_frame[MAXC];
    /* a lost marker's last detection that passed the gate (track.c: confirmed_return) */
    double pend_off[MAXC][2], pend_quad[MAXC][4][2];
    int pend_frame[MAXC];  /* its frame + 1; 0 none */
    int pend_agree[MAXC];  /* successive pairs of them that agreed */
    int suspect_until;     /* frame until which its detections need confirming (a quad of it was
                            * refused for its shape: an occluder is at it) */
    int cut_until;         /* frame until which it is gated against its neighbours' motion too (a
                            * quad of it was refused for its shape) */
    /* consensus.c: this frame's agreement with the other markers' detections (0 not judged,
     * 1 agrees, 2 disagrees), and per camera a single well-shaped detection */
    int cons;
    unsigned char cons_well[MAXC];
    double prev_pos[3];    /* its estimate in frame prev_frame, when measured there */
    int prev_frame;
    unsigned char used[MAXC];  /* gate.c: camera c's detection went into this frame's update */
    unsigned char det_ok[MAXC];/* sh_track_estimate.det_ok, and det_xy */
    double det_xy[MAXC][2];
    /* reported (possibly fused) estimate */
    double pos[3], cov[9];
    /* this frame's per-camera detection bookkeeping */
    int ndet[MAXC];
    int det[MAXC];
} marker;

struct sh_tracker {
    sh_track_options o;
    int ids[MAXM];
    int num_ids;
    int dim, ncam;
    sh_calib calib;
    const sh_calib_camera *cams[MAXC];
    double unit;           /* state units per pixel (1 in 2D; mm/px in 3D, from the first point) */
    int frame, started, updated;
    double dt;
    int nm;
    marker m[MAXM];
    /* rates */
    int locked, nh, nr;    /* nh, nr: active heart / resp harmonics */
    double fh, fr;
    int next_rates;        /* frame of the next rate estimate */
    int prev_frame;        /* the last updated frame before this one (-1 none) */
    int fresh_fit;         /* the last update (re)initialised every filter from its history */
    /* history: one sample every decim frames, ring of SH_TRACK_HISTORY */
    int decim;
    long hist_last;        /* last sample index cleared (-1 none) */
    float *hist;           /* [MAXM][3][SH_TRACK_HISTORY] */
    double *scratch;       /* [MAXM * 3][SH_TRACK_HISTORY] detrended series */
    /* the periodogram's real FFTs (kissfft), one per power of two from 4 x 32 samples to 4 x
     * SH_TRACK_HISTORY (zero padding to 4x gives the grid a quarter of the span's resolution),
     * all set up at create so that no frame allocates */
    void *fft_cfg[RATE_FFT_SIZES];
    float *fft_in;         /* [RATE_FFT_MAX] */
    void *fft_out;         /* kiss_fft_cpx [RATE_FFT_MAX / 2 + 1] */
    double *fft_power;     /* [RATE_FFT_MAX / 2 + 1]: |X|^2 summed over the series */
    double *basis;         /* [RATE_BASIS_TABLES][SH_TRACK_HISTORY][NC]: the fits' basis (rates.c) */
    int band;
    /* spatial model: every marker's filter state in each of the last ring_len frames */
    int ring_len;
    double *ring_x;        /* [ring_len][MAXM][3][NS] */
    unsigned char *ring_ok;/* [ring_len][MAXM]: measured in that frame */
    int *ring_frame;       /* [ring_len] */
    sh_track_motion motion; /* this frame's (consensus.c) */
    sh_track_stats stats;
    /* calcheck.c: RMS and per-view reprojection errors (INFINITY: no point in front of every
     * camera) of the last cal_count <= CAL_WINDOW markers seen once by every camera */
    double cal_rms[CAL_WINDOW], cal_view[MAXC][CAL_WINDOW];
    int cal_next, cal_count;
};

double trk_hx(const sh_tracker *t, const axis_filter *f);
void trk_h_row(const sh_tracker *t, double *h);
double trk_hph(const sh_tracker *t, const axis_filter *f);
void trk_transition(const sh_tracker *t, double dt, double *F);
void trk_predict_filter(const sh_tracker *t, axis_filter *f, const double *F, double dt);
void trk_update_filter(const sh_tracker *t, axis_filter *f, double z, double r);
void trk_init_filter(axis_filter *f, double z, double r, double vvar);
void trk_estimate_rates(sh_tracker *t);
/* Cholesky solve of the m x m (m <= NC) SPD system A c = b (A overwritten), and its inverse when
 * inv is not NULL; 0 on failure. */
int trk_chol_solve(double *A, double *b, int m, double *inv);
/* The median of v[0..n) (sorts v in place); 0 when n = 0. */
double trk_median(double *v, int n);
/* The periodogram's FFT set-up (rates.c), at create; freed by trk_rates_free. */
sh_status trk_rates_init(sh_tracker *t);
void trk_rates_free(sh_tracker *t);
float *trk_hist_at(sh_tracker *t, int mi, int a);
/* track.c */
void trk_marker_pos(const sh_tracker *t, const marker *mk, double *p, double *var);
/* ids.c: auto ids, the markers seen for a second that sh_tracker_judge_ids keeps are confirmed */
void trk_confirm_auto(sh_tracker *t);
/* calcheck.c: this frame's detections (ndet / det counted) into the calibration window */
void trk_calib_observe(sh_tracker *t, const sh_detection *const *det, int num_cameras);
/* gate.c */
int trk_predicted_xy(const sh_tracker *t, const marker *mk, int c, const double *shift,
                     const double *fvar, double xy[2], double S[4]);
/* The filter states of every marker kept for frame (the last ring_len frames, older than now) and
 * which were measured then; 0 when not kept. */
int trk_ring_at(const sh_tracker *t, int frame, const double **rx, const unsigned char **rok);
int trk_spatial_estimate(const sh_tracker *t, const marker *mk, int self, double *corr, double *var);
void trk_update_marker(sh_tracker *t, int i, const sh_detection *const *det, int num_cameras);
/* consensus.c: distance-weighted affine fit (moving least squares) of the values val[j] (dim each)
 * at positions pos[j], over the j < n with use[j] and j != self, evaluated at at[]: the value and
 * its variance (the weighted scatter about the fit). Bandwidth: the 4th nearest contributor; a
 * ridge on the slopes keeps one or two contributors, or a line of them, usable (a translation).
 * 0 when none contributes. Shared by the spatial model (gate.c) and the consensus. */
int trk_field_at(const double (*pos)[2], const double (*val)[3], const unsigned char *use, int n, int self,
                 int dim, const double at[2], double *out, double *var);
/* consensus.c: the detections judged against each other, before the per-marker gate; jumps */
void trk_consensus(sh_tracker *t, const sh_detection *const *det, int num_cameras);
/* Triangulates nv views (three: the best consistent pair when all three are not); 0 when none
 * is consistent within max_reproj; *pair = 1 when a view was dropped. */
int trk_triangulate(const sh_tracker *t, const sh_calib_camera *const *vc, const double *uv, int nv,
                    sh_triangulation *tr, int *pair);
/* quad.c: 1 when detection d of marker mk in camera c has the shape of a whole tag (quad.c) */
int trk_quad_check(sh_tracker *t, marker *mk, int c, const sh_detection *d);
/* 1 when d's quad is the quad ref (centred corners) of `age` frames ago, up to the tag's motion */
int trk_quad_similar(const sh_tracker *t, const double ref[4][2], int age, const sh_detection *d);
void trk_quad_centred(const sh_detection *d, double q[4][2]);
/* d was accepted: it is the reference of the next shape tests */
void trk_quad_learn(sh_tracker *t, marker *mk, int c, const sh_detection *d);

#endif
