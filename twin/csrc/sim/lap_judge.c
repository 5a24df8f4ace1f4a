/* The lap judge in C; see lap_judge.h. */
#include "lap_judge.h"

#include <math.h>
#include <string.h>

void lf_judge_start(lf_judge *j, double length_m, const lf_lap_limits *limits) {
  memset(j, 0, sizeof(*j));
  j->limits = *limits;
  j->length_m = length_m;
}

/* numpy's float modulo (the result takes the divisor's sign), as the Python judge wraps progress steps */
static double np_mod(double a, double b) {
  double m = fmod(a, b);
  if (m != 0.0) {
    if ((b < 0.0) != (m < 0.0)) m += b;
  } else {
    m = copysign(0.0, b);
  }
  return m;
}

int32_t lf_judge_feed(lf_judge *j, const lf_record *r) {
  const lf_lap_limits *lim = &j->limits;
  const double length = j->length_m, t = r->time_s, s = r->progress_m;
  double du, u, last_seen;
  int32_t why = LF_LAP_RUNNING;
  if (j->status != LF_LAP_RUNNING) return j->status;
  if (!j->started) { /* the first record: the start line, wherever 0 wraps */
    j->started = 1;
    j->s_last = s;
    j->u_last = s < length / 2 ? s : s - length;
    j->u_max = j->u_last;
    j->prev_t = t, j->prev_u = j->u_last, j->prev_energy = r->energy_j;
  }
  du = np_mod(s - j->s_last + length / 2, length) - length / 2;
  u = j->u_last + du;
  last_seen = r->line_seen > 0 && t > j->t_seen ? t : j->t_seen;
  if (!(isfinite(r->x_m) && isfinite(r->y_m))) why = LF_LAP_DIVERGED;
  else if (fabs(r->offset_m) > lim->max_cross_track_m) why = LF_LAP_OFF_TRACK;
  else if (fabs(du) > lim->max_progress_jump_m) why = LF_LAP_OFF_TRACK;
  else if (t - last_seen > lim->max_line_lost_s) why = LF_LAP_LINE_LOST;
  else if (u < j->u_max - lim->max_backtrack_m) why = LF_LAP_WRONG_WAY;
  else if (u >= length) why = LF_LAP_COMPLETED;
  else if (t > lim->timeout_s) why = LF_LAP_TIMEOUT;
  /* the running sums of the C loop, so the statistics do not depend on how the trace is fed */
  j->records++;
  j->abs_sum = r->offset_abs_sum_m;
  j->abs_max = r->offset_abs_max_m;
  if (why == LF_LAP_RUNNING) {
    j->prev_t = t, j->prev_u = u, j->prev_energy = r->energy_j;
    j->u_last = u, j->s_last = s, j->t_seen = last_seen;
    if (u > j->u_max) j->u_max = u;
    return LF_LAP_RUNNING;
  }
  j->status = why;
  j->end_t = t, j->end_u = u, j->end_energy = r->energy_j;
  if (why == LF_LAP_COMPLETED && u > j->prev_u) { /* interpolate the crossing between two records */
    double f = (length - j->prev_u) / (u - j->prev_u);
    j->end_t = j->prev_t + f * (t - j->prev_t);
    j->end_energy = j->prev_energy + f * (r->energy_j - j->prev_energy);
    j->end_u = length;
  }
  return why;
}

void lf_judge_fail(lf_judge *j, int32_t status, double t, double energy_j) {
  if (j->status != LF_LAP_RUNNING) return;
  j->status = status;
  j->end_t = t;
  j->end_u = j->started ? j->u_last : 0.0;
  j->end_energy = energy_j;
}
