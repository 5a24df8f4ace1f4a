/* The physics of one reflectance sensor: what the robot's QTR-RC array would read over the track.
 * Python reference: line_sensor.reflectance (compared bit for bit in tests/test_line_sensor.py). */
#ifndef LF_SENSOR_PHYSICS_H
#define LF_SENSOR_PHYSICS_H

#include <stdint.h>

/* Emitter / phototransistor response. The photocurrent is I = rho (1 + noise) / (1 + (h / h_c)^2) for a
 * footprint reflectance rho at height h; the RC discharge time the MCU measures is t = t_unit / I, capped
 * at the read timeout. A footprint of radius aperture + h tan(half_angle) is averaged with weights
 * (1 - r^2/radius^2)^2, so the reading blurs with height as the real sensor's does. */
typedef struct {
  double aperture_m;        /* footprint radius at zero height [m] */
  double half_angle_rad;    /* emitter/detector cone half-angle: footprint growth with height [rad] */
  double falloff_height_m;  /* h_c: height at which the returned light halves [m] */
  double t_unit_us;         /* discharge time for a perfect reflector at zero height [us] */
  double timeout_us;        /* read timeout: the reading of no returned light [us] */
  double noise_rel;         /* relative photocurrent noise, standard deviation [-] */
} lf_sensor_model;

/* The floor texture as MuJoCo holds it: row 0 is the top (largest y). */
typedef struct {
  const uint8_t *data;   /* height x width x nchannel bytes; channel 0 is read as grey */
  int32_t width, height, nchannel;
  double origin_x, origin_y;  /* world position of the lower-left corner [m] */
  double metres_per_pixel;    /* [m] */
} lf_texture;

double lf_footprint_radius(const lf_sensor_model *s, double height_m);
double lf_footprint_reflectance(const lf_texture *tex, double x, double y, double radius_m);
/* Ask the CPU to bring the texels a footprint at (x, y) of radius_m would read into cache, without reading them:
 * a hint that changes no result. The texture is megabytes and a footprint's rows lie a row's stride apart, so a
 * footprint read cold waits on main memory once per row; fetched a tick ahead, while the physics steps, it does not. */
void lf_footprint_prefetch(const lf_texture *tex, double x, double y, double radius_m);
uint16_t lf_raw_reading(const lf_sensor_model *s, double reflectance, double height_m, double noise);

/* splitmix64 (Steele, Lea, Flood 2014): small, seedable, and the same in every language. */
uint64_t lf_rng_next(uint64_t *state);
/* Zero-mean, unit-variance noise: a sum of four uniforms (Irwin-Hall), scaled; pure arithmetic, so
 * bit-identical wherever it runs. */
double lf_noise(uint64_t *state);
/* The generator state a phase's readings draw from (mode: enum lf_mode), from the simulation's seed. */
uint64_t lf_noise_base(uint64_t seed, int32_t mode);
/* The noise of sensor's read-th reading of a phase: a function of (base, read, sensor) alone, so a reading's noise
 * does not depend on the order sensors are read in nor on what came before. The C loop and the processor in the loop
 * (which reads each line when the firmware releases it) then draw the same noise for the same reading. */
double lf_reading_noise(uint64_t base, int64_t read, int32_t sensor);

#endif
