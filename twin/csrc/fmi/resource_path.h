/* Where an FMU's resources are: FMI 2 passes a file URI (RFC 8089: file:///dir/, file:/dir/, file://localhost/dir/,
 * percent-encoded), FMI 3 a path. Both URI spellings and the percent-decoding are what the Modelica Reference FMUs
 * accept too (modelica/Reference-FMUs, Resource/model.c); this is our own implementation. */
#ifndef LF_RESOURCE_PATH_H
#define LF_RESOURCE_PATH_H

/* The resource folder as a path (malloc'ed, the caller frees it), or 0 if `location` is missing or not a local
 * file URI (when is_uri). */
char *lf_resource_dir(const char *location, int is_uri);

#endif
