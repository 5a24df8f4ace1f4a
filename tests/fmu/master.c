/* A co-simulation master with no Python: dlopens an extracted FMI 2 Co-Simulation FMU, steps it to a stop time and
 * prints one Real output. Built and run by tests/test_fmu.py to show that the twin's FMU needs nothing but itself.
 * usage: master UNZIP_DIR MODEL_IDENTIFIER GUID VALUE_REFERENCE STOP_S STEP_S */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
  (void)env, (void)category;
  fprintf(stderr, "[%d] %s: %s\n", (int)status, name, message);
}

#define LOAD(name) fmi2##name##TYPE *name = (fmi2##name##TYPE *)dlsym(lib, "fmi2" #name)

int main(int argc, char **argv) {
  char path[4096], uri[4096];
  void *lib;
  fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
  fmi2Component c;
  fmi2ValueReference vr;
  fmi2Real value = 0.0, t = 0.0, stop, step;
  if (argc != 7) return 2;
  snprintf(path, sizeof(path), "%s/binaries/linux64/%s.so", argv[1], argv[2]);
  snprintf(uri, sizeof(uri), "file://%s/resources", argv[1]);
  vr = (fmi2ValueReference)atoi(argv[4]);
  stop = atof(argv[5]), step = atof(argv[6]);
  lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  if (!lib) {
    fprintf(stderr, "%s\n", dlerror());
    return 1;
  }
  {
    LOAD(Instantiate);
    LOAD(SetupExperiment);
    LOAD(EnterInitializationMode);
    LOAD(ExitInitializationMode);
    LOAD(DoStep);
    LOAD(GetReal);
    LOAD(Terminate);
    LOAD(FreeInstance);
    c = Instantiate("master", fmi2CoSimulation, argv[3], uri, &cb, fmi2False, fmi2False);
    if (!c || SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) || EnterInitializationMode(c) ||
        ExitInitializationMode(c))
      return 1;
    for (; t < stop - 1e-9; t += step)
      if (DoStep(c, t, step, fmi2True)) return 1;
    if (GetReal(c, &vr, 1, &value)) return 1;
    Terminate(c);
    FreeInstance(c);
  }
  printf("%.17g\n", value);
  return 0;
}
