/* Where an FMU's resources are; see resource_path.h. */
#include "resource_path.h"

#include <stdlib.h>
#include <string.h>

static int hex(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

char *lf_resource_dir(const char *location, int is_uri) {
  const char *p = location;
  char *out, *q;
  if (!location) return 0;
  if (!is_uri) return strdup(location);
  if (strncmp(p, "file:", 5) != 0) return 0;
  p += 5;
  if (strncmp(p, "//", 2) == 0) { /* an authority: empty or localhost */
    p += 2;
    if (strncmp(p, "localhost", 9) == 0) p += 9;
    if (*p != '/') return 0;
  }
  out = q = malloc(strlen(p) + 1);
  if (!out) return 0;
  while (*p) {
    if (p[0] == '%' && hex(p[1]) >= 0 && hex(p[2]) >= 0) {
      *q++ = (char)(hex(p[1]) * 16 + hex(p[2]));
      p += 3;
    } else {
      *q++ = *p++;
    }
  }
  *q = '\0';
  return out;
}
