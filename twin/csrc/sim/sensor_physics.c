#include "sensor_physics.h"

#include <math.h>

double lf_footprint_radius(const lf_sensor_model *s, double height_m) {
  return s->aperture_m + height_m * tan(s->half_angle_rad);
}

/* The texel arithmetic is Python's (line_sensor.reflectance.footprint_reflectance), operation for operation, so the
 * result is bit-identical; only what repeats is computed once: each column's dx^2, each row's dy^2, and rows that lie
 * wholly outside the disc are skipped (q = (dx^2 + dy^2) / r^2 >= dy^2 / r^2 in floating point too: rounding is
 * monotonic, so such a row adds nothing). */
#define LF_FOOTPRINT_COLUMNS 128

/* The texels [c0, c1] x [r0, r1] of the square around a disc at (x, y) of radius_m, clipped to the texture; 0 when
 * none is on it. Computed in doubles first: a position far off the texture (or NaN) must not overflow the indices. */
static int footprint_box(const lf_texture *tex, double x, double y, double radius_m, int32_t *c0, int32_t *c1,
                         int32_t *r0, int32_t *r1) {
  const double mpp = tex->metres_per_pixel;
  double c0f = floor((x - radius_m - tex->origin_x) / mpp), c1f = floor((x + radius_m - tex->origin_x) / mpp);
  double r0f = floor(tex->height - (y + radius_m - tex->origin_y) / mpp);
  double r1f = floor(tex->height - (y - radius_m - tex->origin_y) / mpp);
  if (!(c1f >= 0.0 && r1f >= 0.0 && c0f < tex->width && r0f < tex->height)) return 0;
  *c0 = c0f < 0.0 ? 0 : (int32_t)c0f;
  *r0 = r0f < 0.0 ? 0 : (int32_t)r0f;
  *c1 = c1f > tex->width - 1 ? tex->width - 1 : (int32_t)c1f;
  *r1 = r1f > tex->height - 1 ? tex->height - 1 : (int32_t)r1f;
  return 1;
}

double lf_footprint_reflectance(const lf_texture *tex, double x, double y, double radius_m) {
  const double mpp = tex->metres_per_pixel;
  const double inv_r2 = 1.0 / (radius_m * radius_m); /* a multiply per texel, not a divide */
  double sum = 0.0, weight = 0.0, dx2[LF_FOOTPRINT_COLUMNS];
  int32_t c0, c1, r0, r1, r, c, cached;
  if (!footprint_box(tex, x, y, radius_m, &c0, &c1, &r0, &r1)) c0 = r0 = 0, c1 = r1 = -1; /* no texel: the fallback */
  cached = c1 - c0 < LF_FOOTPRINT_COLUMNS;
  if (cached)
    for (c = c0; c <= c1; c++) {
      double dx = tex->origin_x + (c + 0.5) * mpp - x;
      dx2[c - c0] = dx * dx;
    }
  for (r = r0; r <= r1; r++) {
    const double dy = tex->origin_y + (tex->height - r - 0.5) * mpp - y, dy2 = dy * dy;
    const uint8_t *row = tex->data + (int64_t)r * tex->width * tex->nchannel;
    if (!(dy2 * inv_r2 < 1.0)) continue;
    for (c = c0; c <= c1; c++) {
      double dx = cached ? 0.0 : tex->origin_x + (c + 0.5) * mpp - x;
      double q = ((cached ? dx2[c - c0] : dx * dx) + dy2) * inv_r2;
      if (q < 1.0) {
        double w = (1.0 - q) * (1.0 - q);
        sum += w * row[(int64_t)c * tex->nchannel];
        weight += w;
      }
    }
  }
  if (weight > 0.0) return sum / (255.0 * weight);
  /* a footprint smaller than a texel: the texel under the point, if the point is on the texture */
  c = (int32_t)floor((x - tex->origin_x) / mpp);
  r = (int32_t)floor(tex->height - (y - tex->origin_y) / mpp);
  if (c < 0 || r < 0 || c >= tex->width || r >= tex->height) return 0.0;
  return tex->data[((int64_t)r * tex->width + c) * tex->nchannel] / 255.0;
}

#if defined(__GNUC__) || defined(__clang__)
#define LF_PREFETCH(address) __builtin_prefetch((address), 0, 1)
#else
#define LF_PREFETCH(address) ((void)(address))
#endif
#define LF_CACHE_LINE 64 /* [bytes]; another real line size only makes the hint less exact */

void lf_footprint_prefetch(const lf_texture *tex, double x, double y, double radius_m) {
  int32_t c0, c1, r0, r1, r;
  int64_t b;
  if (!footprint_box(tex, x, y, radius_m, &c0, &c1, &r0, &r1)) return;
  for (r = r0; r <= r1; r++) { /* each cache line the row's texels c0..c1 lie in, once */
    const uint8_t *row = tex->data + (int64_t)r * tex->width * tex->nchannel;
    const uintptr_t first = (uintptr_t)(row + (int64_t)c0 * tex->nchannel);
    const uintptr_t last = (uintptr_t)(row + ((int64_t)c1 + 1) * tex->nchannel - 1);
    for (b = 0; (uintptr_t)b <= last / LF_CACHE_LINE - first / LF_CACHE_LINE; b++)
      LF_PREFETCH((const uint8_t *)(first - first % LF_CACHE_LINE + (uintptr_t)b * LF_CACHE_LINE));
  }
}

uint16_t lf_raw_reading(const lf_sensor_model *s, double reflectance, double height_m, double noise) {
  double h = height_m / s->falloff_height_m;
  double current = reflectance * (1.0 + s->noise_rel * noise) / (1.0 + h * h);
  double t;
  if (!(current > 0.0)) return (uint16_t)s->timeout_us;
  t = s->t_unit_us / current;
  if (t >= s->timeout_us) return (uint16_t)s->timeout_us;
  return (uint16_t)(t + 0.5);
}

uint64_t lf_rng_next(uint64_t *state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

uint64_t lf_noise_base(uint64_t seed, int32_t mode) {
  uint64_t state = seed ^ ((uint64_t)(uint32_t)mode * 0xD1B54A32D192ED03ull);
  return lf_rng_next(&state);
}

double lf_reading_noise(uint64_t base, int64_t read, int32_t sensor) {
  uint64_t key = ((uint64_t)read << 8) | (uint8_t)sensor, state = base ^ lf_rng_next(&key);
  return lf_noise(&state);
}

double lf_noise(uint64_t *state) {
  double sum = 0.0;
  int i;
  for (i = 0; i < 4; i++) sum += (double)(lf_rng_next(state) >> 11) * (1.0 / 9007199254740992.0);
  return (sum - 2.0) * 1.7320508075688772; /* variance of the sum is 4/12 */
}
