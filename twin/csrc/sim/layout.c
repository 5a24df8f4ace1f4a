/* The layout Python mirrors (twin.core.native): every field's offset and size, so a stale build or a mirror that drifted
 * from the C fails at import instead of reading the wrong bytes; and the status codes' names (twin.core.outcomes). */
#include <stddef.h>

#include <mujoco/mujoco.h>

#include "twin_core.h"

static const lf_field fields[] = {
  LF_FIELD(lf_sim, magic), LF_FIELD(lf_sim, layout_version), LF_FIELD(lf_sim, error),
  LF_FIELD(lf_sim, model_signature), LF_FIELD(lf_sim, nsensor), LF_FIELD(lf_sim, sensor_site),
  LF_FIELD(lf_sim, sensor_body), LF_FIELD(lf_sim, texture_id), LF_FIELD(lf_sim, actuator_left),
  LF_FIELD(lf_sim, actuator_right), LF_FIELD(lf_sim, dof_left), LF_FIELD(lf_sim, dof_right),
  LF_FIELD(lf_sim, axle_site), LF_FIELD(lf_sim, root_body), LF_FIELD(lf_sim, record_capacity),
  LF_FIELD(lf_sim, centre_adr), LF_FIELD(lf_sim, centre_count), LF_FIELD(lf_sim, texture_origin_x),
  LF_FIELD(lf_sim, texture_origin_y), LF_FIELD(lf_sim, texture_metres_per_pixel), LF_FIELD(lf_sim, supply_voltage),
  LF_FIELD(lf_sim, timestep), LF_FIELD(lf_sim, sensor), LF_FIELD(lf_sim, firmware), LF_FIELD(lf_sim, seed),
  LF_FIELD(lf_sim, rng), LF_FIELD(lf_sim, ticks), LF_FIELD(lf_sim, records_written), LF_FIELD(lf_sim, segment),
  LF_FIELD(lf_sim, phase_start_time), LF_FIELD(lf_sim, last_time), LF_FIELD(lf_sim, energy_j),
  LF_FIELD(lf_sim, offset_abs_sum_m), LF_FIELD(lf_sim, offset_abs_max_m), LF_FIELD(lf_sim, fw), LF_FIELD(lf_sim, raw),
  LF_FIELD(lf_sim, judge_on), LF_FIELD(lf_sim, stop_raised), LF_FIELD(lf_sim, deadline_s),
  LF_FIELD(lf_sim, judge), LF_FIELD(lf_sim, timing), LF_FIELD(lf_sim, duty_now), LF_FIELD(lf_sim, duty_next),
  LF_FIELD(lf_sim, apply_time_s), LF_FIELD(lf_sim, pending), LF_FIELD(lf_sim, pad),
  LF_FIELD(lf_sim, reads), LF_FIELD(lf_sim, power), LF_FIELD(lf_sim, terminal_min_v), LF_FIELD(lf_sim, power_off),
  LF_FIELD(lf_sim, pad_power),

  LF_FIELD(lf_power, battery_v), LF_FIELD(lf_power, source_ohm), LF_FIELD(lf_power, regulator_v),
  LF_FIELD(lf_power, regulator_min_input_v),

  LF_FIELD(lf_timing, release_us), LF_FIELD(lf_timing, compute_us), LF_FIELD(lf_timing, compute_centred_us),
  LF_FIELD(lf_timing, compute_lost_us), LF_FIELD(lf_timing, compute_calibrate_us), LF_FIELD(lf_timing, pwm_counts),

  LF_FIELD(lf_lap_limits, max_cross_track_m), LF_FIELD(lf_lap_limits, max_progress_jump_m),
  LF_FIELD(lf_lap_limits, max_line_lost_s), LF_FIELD(lf_lap_limits, timeout_s),
  LF_FIELD(lf_lap_limits, max_backtrack_m),

  LF_FIELD(lf_judge, limits), LF_FIELD(lf_judge, length_m), LF_FIELD(lf_judge, status), LF_FIELD(lf_judge, started),
  LF_FIELD(lf_judge, records), LF_FIELD(lf_judge, u_last), LF_FIELD(lf_judge, s_last), LF_FIELD(lf_judge, u_max),
  LF_FIELD(lf_judge, t_seen),
  LF_FIELD(lf_judge, prev_t), LF_FIELD(lf_judge, prev_u), LF_FIELD(lf_judge, prev_energy), LF_FIELD(lf_judge, abs_sum),
  LF_FIELD(lf_judge, abs_max), LF_FIELD(lf_judge, end_t), LF_FIELD(lf_judge, end_u), LF_FIELD(lf_judge, end_energy),

  LF_FIELD(lf_record, time_s), LF_FIELD(lf_record, x_m), LF_FIELD(lf_record, y_m), LF_FIELD(lf_record, yaw_rad),
  LF_FIELD(lf_record, e_rad), LF_FIELD(lf_record, v_mps), LF_FIELD(lf_record, omega_radps),
  LF_FIELD(lf_record, u_left_v), LF_FIELD(lf_record, u_right_v), LF_FIELD(lf_record, wheel_left_radps),
  LF_FIELD(lf_record, wheel_right_radps), LF_FIELD(lf_record, position), LF_FIELD(lf_record, line_seen),
  LF_FIELD(lf_record, mode), LF_FIELD(lf_record, energy_j), LF_FIELD(lf_record, height_m),
  LF_FIELD(lf_record, progress_m), LF_FIELD(lf_record, offset_m), LF_FIELD(lf_record, offset_abs_sum_m),
  LF_FIELD(lf_record, offset_abs_max_m), LF_FIELD(lf_record, raw_us), LF_FIELD(lf_record, calibrated),

  LF_FIELD(lf_params, count), LF_FIELD(lf_params, pitch_m), LF_FIELD(lf_params, sensor_distance_m),
  LF_FIELD(lf_params, v_max), LF_FIELD(lf_params, k_b), LF_FIELD(lf_params, k_p), LF_FIELD(lf_params, k_i),
  LF_FIELD(lf_params, k_d), LF_FIELD(lf_params, dt_s), LF_FIELD(lf_params, wheel_radius_m),
  LF_FIELD(lf_params, half_track_m), LF_FIELD(lf_params, wheel_speed_max), LF_FIELD(lf_params, accel_max),
  LF_FIELD(lf_params, integral_limit), LF_FIELD(lf_params, cal_duty), LF_FIELD(lf_params, cal_sweep_rad),
  LF_FIELD(lf_params, cal_sweeps),

  LF_FIELD(lf_state, cal_min), LF_FIELD(lf_state, cal_max), LF_FIELD(lf_state, value), LF_FIELD(lf_state, position),
  LF_FIELD(lf_state, last_position), LF_FIELD(lf_state, line_seen), LF_FIELD(lf_state, mode), LF_FIELD(lf_state, tick),
  LF_FIELD(lf_state, e), LF_FIELD(lf_state, e_prev), LF_FIELD(lf_state, integral), LF_FIELD(lf_state, v),
  LF_FIELD(lf_state, omega), LF_FIELD(lf_state, duty_left), LF_FIELD(lf_state, duty_right),
  LF_FIELD(lf_state, call_min), LF_FIELD(lf_state, call_max), LF_FIELD(lf_state, call_reads),

  LF_FIELD(lf_sensor_model, aperture_m), LF_FIELD(lf_sensor_model, half_angle_rad),
  LF_FIELD(lf_sensor_model, falloff_height_m), LF_FIELD(lf_sensor_model, t_unit_us),
  LF_FIELD(lf_sensor_model, timeout_us), LF_FIELD(lf_sensor_model, noise_rel),

  LF_FIELD(lf_texture, data), LF_FIELD(lf_texture, width), LF_FIELD(lf_texture, height),
  LF_FIELD(lf_texture, nchannel), LF_FIELD(lf_texture, origin_x), LF_FIELD(lf_texture, origin_y),
  LF_FIELD(lf_texture, metres_per_pixel),
};

int32_t lf_layout(const lf_field **out) {
  *out = fields;
  return (int32_t)(sizeof(fields) / sizeof(fields[0]));
}

#define LF_STATUS(code) {#code, code}

static const lf_status_name statuses[] = {
  LF_STATUS(LF_OK), LF_STATUS(LF_ERR_LAYOUT), LF_STATUS(LF_ERR_MODEL), LF_STATUS(LF_ERR_CAPACITY),
  LF_STATUS(LF_ERR_SENSORS), LF_STATUS(LF_ERR_ID), LF_STATUS(LF_ERR_CENTRE), LF_STATUS(LF_ERR_STATE),
  LF_STATUS(LF_ERR_RAY), LF_STATUS(LF_ERR_FIRMWARE), LF_STATUS(LF_STALLED),
  LF_STATUS(LF_LAP_RUNNING), LF_STATUS(LF_LAP_COMPLETED), LF_STATUS(LF_LAP_OFF_TRACK), LF_STATUS(LF_LAP_LINE_LOST),
  LF_STATUS(LF_LAP_TIMEOUT), LF_STATUS(LF_LAP_DIVERGED), LF_STATUS(LF_LAP_CALIBRATION), LF_STATUS(LF_LAP_REFUSED),
  LF_STATUS(LF_LAP_WRONG_WAY),
};

int32_t lf_status_names(const lf_status_name **out) {
  *out = statuses;
  return (int32_t)(sizeof(statuses) / sizeof(statuses[0]));
}

int32_t lf_sizes(int64_t *out, int32_t n) {
  const int64_t sizes[] = {
    (int64_t)sizeof(lf_sim), (int64_t)sizeof(lf_record), (int64_t)sizeof(lf_params), (int64_t)sizeof(lf_state),
    (int64_t)sizeof(lf_sensor_model), (int64_t)sizeof(lf_texture), (int64_t)mjVERSION_HEADER,
    (int64_t)sizeof(mjtNum), LF_MAX_SENSORS, LF_LAYOUT_VERSION, LF_SIGNATURE,
  };
  const int32_t count = (int32_t)(sizeof(sizes) / sizeof(sizes[0]));
  int32_t i;
  for (i = 0; i < n && i < count; i++) out[i] = sizes[i];
  return count;
}
