/* An FMI 3.0 test model (co-simulation and model exchange) for tests/test_fmu_compiled.py.
 *
 * x is one continuous state with der(x) = -k*x and x(start) = 1; u_out = u passes the real
 * input straight through. The other outputs expose what the FMU received: an array
 * y = [x, 2x, 3x], a 2x2 matrix m[i,j] = (10i + j) x, the 64-bit integer inputs echoed, the
 * String parameter (echoed and as its length), the array parameter offsets (as
 * offsets[1] + 10 offsets[2]), and the start time and tolerance the importer passed to
 * fmi3EnterInitializationMode. Functions the tests never reach are generated as stubs that
 * return fmi3Error (compiled_fmus.py).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

enum { VR_TIME, VR_I64, VR_U64, VR_I64_OUT, VR_U64_OUT, VR_Y, VR_M, VR_K, VR_LABEL,
       VR_LABEL_OUT, VR_LABEL_LENGTH, VR_TOL_SEEN, VR_START_SEEN, VR_X, VR_DER_X, VR_BLOB, VR_U,
       VR_U_OUT, VR_OFFSETS, VR_OFFSET_SUM };

typedef struct {
    double time, x, k, tolerance, start, u, offsets[2];
    fmi3Int64 i64;
    fmi3UInt64 u64;
    char label[256];
} Probe;

static int value_of(const Probe *p, fmi3ValueReference vr, size_t *count, double *out) {
    switch (vr) {
    case VR_TIME: out[(*count)++] = p->time; break;
    case VR_Y: for (int i = 1; i <= 3; i++) out[(*count)++] = i * p->x; break;
    case VR_M:
        for (int i = 1; i <= 2; i++)
            for (int j = 1; j <= 2; j++) out[(*count)++] = (10 * i + j) * p->x;
        break;
    case VR_K: out[(*count)++] = p->k; break;
    case VR_TOL_SEEN: out[(*count)++] = p->tolerance; break;
    case VR_START_SEEN: out[(*count)++] = p->start; break;
    case VR_X: out[(*count)++] = p->x; break;
    case VR_U: case VR_U_OUT: out[(*count)++] = p->u; break;
    case VR_OFFSETS: out[(*count)++] = p->offsets[0]; out[(*count)++] = p->offsets[1]; break;
    case VR_OFFSET_SUM: out[(*count)++] = p->offsets[0] + 10 * p->offsets[1]; break;
    case VR_DER_X: out[(*count)++] = -p->k * p->x; break;
    default: return -1;
    }
    return 0;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[]) {
    return fmi3OK;
}

static fmi3Instance instantiate(void) {
    Probe *p = calloc(1, sizeof(Probe));
    if (p) {
        p->x = 1.0;
        p->k = 1.0;
        p->tolerance = -1.0;
        strcpy(p->label, "none");
    }
    return p;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    return instantiate();
}

fmi3Instance fmi3InstantiateModelExchange(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage) {
    return instantiate();
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Probe *p = instance;
    p->tolerance = toleranceDefined ? tolerance : -1.0;
    p->start = startTime;
    p->time = startTime;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return fmi3OK; }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance instance) { return fmi3OK; }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues) {
    size_t count = 0;
    for (size_t i = 0; i < nvr; i++)
        if (value_of(instance, vr[i], &count, values) != 0) return fmi3Error;
    return count == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    Probe *p = instance;
    size_t count = 0;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_K) p->k = values[count++];
        else if (vr[i] == VR_X) p->x = values[count++];
        else if (vr[i] == VR_U) p->u = values[count++];
        else if (vr[i] == VR_OFFSETS) {
            p->offsets[0] = values[count++];
            p->offsets[1] = values[count++];
        } else return fmi3Error;
    }
    return count == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Int64 values[], size_t nValues) {
    Probe *p = instance;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_I64 || vr[i] == VR_I64_OUT) values[i] = p->i64;
        else return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Int64 values[], size_t nValues) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_I64) return fmi3Error;
        ((Probe *)instance)->i64 = values[i];
    }
    return fmi3OK;
}

fmi3Status fmi3GetUInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         fmi3UInt64 values[], size_t nValues) {
    Probe *p = instance;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_U64 || vr[i] == VR_U64_OUT) values[i] = p->u64;
        else return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetUInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3UInt64 values[], size_t nValues) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_U64) return fmi3Error;
        ((Probe *)instance)->u64 = values[i];
    }
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Int32 values[], size_t nValues) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_LABEL_LENGTH) return fmi3Error;
        values[i] = (fmi3Int32)strlen(((Probe *)instance)->label);
    }
    return fmi3OK;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         fmi3String values[], size_t nValues) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_LABEL && vr[i] != VR_LABEL_OUT) return fmi3Error;
        values[i] = ((Probe *)instance)->label;
    }
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3String values[], size_t nValues) {
    Probe *p = instance;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_LABEL || strlen(values[i]) >= sizeof p->label) return fmi3Error;
        strcpy(p->label, values[i]);
    }
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Probe *p = instance;
    p->x *= exp(-p->k * communicationStepSize); /* the exact solution over the step */
    p->time = currentCommunicationPoint + communicationStepSize;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = p->time;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    ((Probe *)instance)->time = time;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 states[],
                                   size_t n) {
    ((Probe *)instance)->x = states[0];
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 states[], size_t n) {
    states[0] = ((Probe *)instance)->x;
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t n) {
    Probe *p = instance;
    derivatives[0] = -p->k * p->x;
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t n) {
    nominals[0] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 indicators[], size_t n) {
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n) {
    *n = 1;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n) {
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}
