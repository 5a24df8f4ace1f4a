/* The functions of the FMI 3.0 standard that the twin's Co-Simulation FMU does not support: present, as an importer
 * may look every one up, and each logs that it is not supported and returns fmi3Error. */
#include "fmi3Functions.h"

fmi3Status lf_fmi3_unsupported(fmi3Instance c, const char *what); /* fmi3_face.c */
#define NO(what) return lf_fmi3_unsupported(c, what)

fmi3Status fmi3EnterEventMode(fmi3Instance c) { NO("fmi3EnterEventMode"); }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { NO("fmi3EnterStepMode (no event mode)"); }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
  (void)vr, (void)n, (void)v;
  NO("fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
  (void)vr, (void)n, (void)v;
  NO("fmi3SetClock");
}
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *n) {
  (void)vr, (void)n;
  NO("fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t ed[],
                                       fmi3ValueReference independents[], size_t ei[], fmi3DependencyKind kinds[],
                                       size_t n) {
  (void)dependent, (void)ed, (void)independents, (void)ei, (void)kinds, (void)n;
  NO("fmi3GetVariableDependencies");
}
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s) { (void)s; NO("fmi3GetFMUState"); }
fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s) { (void)s; NO("fmi3SetFMUState"); }
fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s) { (void)s; NO("fmi3FreeFMUState"); }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *n) {
  (void)s, (void)n;
  NO("fmi3SerializedFMUStateSize");
}
fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte b[], size_t n) {
  (void)s, (void)b, (void)n;
  NO("fmi3SerializeFMUState");
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte b[], size_t n, fmi3FMUState *s) {
  (void)s, (void)b, (void)n;
  NO("fmi3DeserializeFMUState");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference u[], size_t nu,
                                        const fmi3ValueReference k[], size_t nk, const fmi3Float64 seed[],
                                        size_t ns, fmi3Float64 out[], size_t no) {
  (void)u, (void)nu, (void)k, (void)nk, (void)seed, (void)ns, (void)out, (void)no;
  NO("fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference u[], size_t nu,
                                    const fmi3ValueReference k[], size_t nk, const fmi3Float64 seed[], size_t ns,
                                    fmi3Float64 out[], size_t no) {
  (void)u, (void)nu, (void)k, (void)nk, (void)seed, (void)ns, (void)out, (void)no;
  NO("fmi3GetAdjointDerivative");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) { NO("fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) { NO("fmi3ExitConfigurationMode"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 iv[],
                                  fmi3IntervalQualifier q[]) {
  (void)vr, (void)n, (void)iv, (void)q;
  NO("fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier q[]) {
  (void)vr, (void)n, (void)counters, (void)resolutions, (void)q;
  NO("fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[]) {
  (void)vr, (void)n, (void)shifts;
  NO("fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
  (void)vr, (void)n, (void)counters, (void)resolutions;
  NO("fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 iv[]) {
  (void)vr, (void)n, (void)iv;
  NO("fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
  (void)vr, (void)n, (void)counters, (void)resolutions;
  NO("fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[]) {
  (void)vr, (void)n, (void)shifts;
  NO("fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
  (void)vr, (void)n, (void)counters, (void)resolutions;
  NO("fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { NO("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *needUpdate, fmi3Boolean *terminate,
                                    fmi3Boolean *nominalsChanged, fmi3Boolean *valuesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
  (void)needUpdate, (void)terminate, (void)nominalsChanged, (void)valuesChanged, (void)nextEventTimeDefined,
      (void)nextEventTime;
  NO("fmi3UpdateDiscreteStates");
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { NO("fmi3EnterContinuousTimeMode"); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
  NO("fmi3CompletedIntegratorStep");
}
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) { (void)time; NO("fmi3SetTime"); }
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t n) {
  (void)x, (void)n;
  NO("fmi3SetContinuousStates");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t n) {
  (void)dx, (void)n;
  NO("fmi3GetContinuousStateDerivatives");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t n) {
  (void)z, (void)n;
  NO("fmi3GetEventIndicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t n) {
  (void)x, (void)n;
  NO("fmi3GetContinuousStates");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t n) {
  (void)nominals, (void)n;
  NO("fmi3GetNominalsOfContinuousStates");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { (void)n; NO("fmi3GetNumberOfEventIndicators"); }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) {
  (void)n;
  NO("fmi3GetNumberOfContinuousStates");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
  (void)vr, (void)n, (void)orders, (void)values, (void)nValues;
  NO("fmi3GetOutputDerivatives");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clock, fmi3Float64 activationTime) {
  (void)clock, (void)activationTime;
  NO("fmi3ActivateModelPartition");
}
