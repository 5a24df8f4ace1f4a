#include "lf_wire.h"

static int put_str(char *p, const char *s) {
  int n = 0;
  while (s[n]) p[n] = s[n], n++;
  return n;
}

/* Decimal digits by subtracting powers of ten: no 32-bit division, which costs the AVR ~600 cycles a digit. */
static int put_uint(char *p, uint32_t u) {
  static const uint32_t tens[9] = {1000000000UL, 100000000UL, 10000000UL, 1000000UL, 100000UL,
                                   10000UL,      1000UL,      100UL,      10UL};
  int n = 0, i;
  for (i = 0; i < 9; i++) {
    char digit = '0';
    while (u >= tens[i]) u -= tens[i], digit++;
    if (digit != '0' || n) p[n++] = digit;
  }
  p[n++] = (char)('0' + u);
  return n;
}

static int put_int(char *p, int32_t v) {
  if (v >= 0) return put_uint(p, (uint32_t)v);
  p[0] = '-';
  return 1 + put_uint(p + 1, (uint32_t)(-(v + 1)) + 1u); /* -INT32_MIN overflows; this does not */
}

/* "*CS\n" after the body buf[1..n): XOR of the bytes between '$' and '*' */
static int finish(char *buf, int n) {
  static const char hex[] = "0123456789ABCDEF";
  uint8_t x = 0;
  int i;
  for (i = 1; i < n; i++) x ^= (uint8_t)buf[i];
  buf[n++] = '*';
  buf[n++] = hex[x >> 4];
  buf[n++] = hex[x & 15];
  buf[n++] = '\n';
  buf[n] = 0;
  return n;
}

int lf_wire_header(char *buf, int32_t sensors, int32_t dt_us, int32_t every) {
  int n = put_str(buf, "$LFH,");
  n += put_int(buf + n, LF_WIRE_VERSION);
  buf[n++] = ',';
  n += put_int(buf + n, sensors);
  buf[n++] = ',';
  n += put_int(buf + n, dt_us);
  buf[n++] = ',';
  n += put_int(buf + n, every);
  return finish(buf, n);
}

int lf_wire_sample(char *buf, uint32_t t_ms, int32_t pos, int32_t seen, int32_t wl_crad, int32_t wr_crad) {
  int n = put_str(buf, "$LFS,");
  n += put_uint(buf + n, t_ms);
  buf[n++] = ',';
  n += put_int(buf + n, pos);
  buf[n++] = ',';
  n += put_int(buf + n, seen);
  buf[n++] = ',';
  n += put_int(buf + n, wl_crad);
  buf[n++] = ',';
  n += put_int(buf + n, wr_crad);
  return finish(buf, n);
}

int lf_wire_start(char *buf, uint32_t t_ms) {
  int n = put_str(buf, "$LFE,");
  n += put_uint(buf + n, t_ms);
  n += put_str(buf + n, ",START");
  return finish(buf, n);
}

int lf_wire_lap(char *buf, uint32_t t_ms, uint32_t lap_ms) {
  int n = put_str(buf, "$LFE,");
  n += put_uint(buf + n, t_ms);
  n += put_str(buf + n, ",LAP,");
  n += put_uint(buf + n, lap_ms);
  return finish(buf, n);
}
