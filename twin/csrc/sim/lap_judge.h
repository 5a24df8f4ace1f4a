/* The lap judge in C, record by record: what twin.core.lap.LapJudge decides chunk by chunk, for a loop with no Python
 * beside it (the FMU). Python reference: twin.core.lap.LapJudge (tests/test_lap_judge_c.py feeds both the same
 * trace and compares their outcomes).
 *
 * Progress is the arc length of the centre-line point nearest the centre of rotation (lf_locate), unwrapped record
 * by record; the lap completes when it reaches the track length, at a time interpolated between the two records
 * around the crossing. It fails off the track (too far from the line, or a jump to another part of it), with the
 * line lost too long, going the wrong way (turned round: progress fell max_backtrack_m behind the furthest it had
 * reached), after the timeout, or when the physics diverges. The first event wins; at the same record, the
 * one listed first in lf_judge_feed wins, as in Python.
 */
#ifndef LF_LAP_JUDGE_H
#define LF_LAP_JUDGE_H

#include <stdint.h>

#include "lf_record.h"
#include "lf_status.h" /* enum lf_lap_status: how a lap ended, beside the simulation's codes */

/* Failure thresholds: twin.core.lap.LapLimits. Lengths [m], times [s]. */
typedef struct {
  double max_cross_track_m;
  double max_progress_jump_m;
  double max_line_lost_s;
  double timeout_s;
  double max_backtrack_m;
} lf_lap_limits;

typedef struct {
  lf_lap_limits limits;
  double length_m;          /* track length [m] */
  int32_t status;           /* enum lf_lap_status */
  int32_t started;          /* a record has been fed */
  int64_t records;          /* records accounted for (up to and including the one that ended the lap) */
  double u_last, s_last;    /* unwrapped and raw progress at the last record [m] */
  double u_max;             /* the furthest unwrapped progress so far [m] */
  double t_seen;            /* last time the line was seen [s] */
  double prev_t, prev_u, prev_energy; /* the last record before the current one */
  double abs_sum, abs_max;  /* cross-track statistics of the C loop's running sums [m] */
  double end_t, end_u, end_energy;    /* where the lap ended (time [s], progress [m], energy [J]) */
} lf_judge;

void lf_judge_start(lf_judge *j, double length_m, const lf_lap_limits *limits);
/* Take the next record; returns the status after it. Records after the end are ignored. */
int32_t lf_judge_feed(lf_judge *j, const lf_record *r);
/* End the lap from outside the trace (calibration, divergence, a refused head) at time t [s]. */
void lf_judge_fail(lf_judge *j, int32_t status, double t, double energy_j);

#endif
