/* An FMI 2.0 test model (co-simulation and model exchange) for tests/test_fmu_compiled.py.
 *
 * x is one continuous state with der(x) = -k*x and x(start) = 1, seen as the output y; n_out
 * echoes the Integer input n; tol_seen and start_seen report what the importer passed to
 * fmi2SetupExperiment. Functions the tests never reach are generated as stubs that return
 * fmi2Error (compiled_fmus.py).
 */
#include <math.h>
#include <stdlib.h>

#include "fmi2Functions.h"

enum { VR_X, VR_DER_X, VR_K, VR_Y, VR_TOL_SEEN, VR_START_SEEN, VR_N, VR_N_OUT };

typedef struct {
    double x, k, tolerance, start;
    fmi2Integer n;
} Probe;

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Probe *p = calloc(1, sizeof(Probe));
    if (p) {
        p->x = 1.0;
        p->k = 1.0;
        p->tolerance = -1.0;
    }
    return p;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Probe *p = c;
    p->tolerance = toleranceDefined ? tolerance : -1.0;
    p->start = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_X: case VR_Y: value[i] = p->x; break;
        case VR_DER_X: value[i] = -p->k * p->x; break;
        case VR_K: value[i] = p->k; break;
        case VR_TOL_SEEN: value[i] = p->tolerance; break;
        case VR_START_SEEN: value[i] = p->start; break;
        default: return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Probe *p = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_K) p->k = value[i];
        else if (vr[i] == VR_X) p->x = value[i];
        else return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_N && vr[i] != VR_N_OUT) return fmi2Error;
        value[i] = ((Probe *)c)->n;
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_N) return fmi2Error;
        ((Probe *)c)->n = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Probe *p = c;
    p->x *= exp(-p->k * communicationStepSize); /* the exact solution over the step */
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    ((Probe *)c)->x = x[0];
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    x[0] = ((Probe *)c)->x;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    Probe *p = c;
    derivatives[0] = -p->k * p->x;
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[],
                                             size_t nx) {
    x_nominal[0] = 1.0;
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    return fmi2OK;
}
