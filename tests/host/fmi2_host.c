/* A minimal non-Python FMI 2.0 co-simulation host (what fmusim or a Simulink S-function does):
 * load an extracted FMU's binary, instantiate, set one Real input, step, print Real outputs.
 * Used by tests/test_third_party_host.py to check docs/third_party.md on this machine.
 *
 * usage: fmi2_host BINARY RESOURCE_URI GUID STOP STEP INPUT_VR INPUT_VALUE OUTPUT_VR...
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%s %d] ", name, (int)status);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}

#define LOAD(type, name) type name = (type)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 3; }

int main(int argc, char **argv) {
    if (argc < 9) { fprintf(stderr, "usage: see source\n"); return 2; }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
    LOAD(fmi2InstantiateTYPE *, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode)
    LOAD(fmi2SetRealTYPE *, fmi2SetReal)
    LOAD(fmi2GetRealTYPE *, fmi2GetReal)
    LOAD(fmi2DoStepTYPE *, fmi2DoStep)
    LOAD(fmi2TerminateTYPE *, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance)
    void (*finalize)(void) = (void (*)(void))dlsym(lib, "finalizePythonInterpreter");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, argv[3], argv[2], &callbacks, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "instantiation failed\n"); return 4; }
    double stop = atof(argv[4]), h = atof(argv[5]);
    fmi2ValueReference in_vr = (fmi2ValueReference)atoi(argv[6]);
    fmi2Real in_value = atof(argv[7]);
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning) return 5;
    if (fmi2EnterInitializationMode(c) > fmi2Warning) return 5;
    if (fmi2ExitInitializationMode(c) > fmi2Warning) return 5;
    long steps = (long)(stop / h + 0.5);
    for (long k = 0; k < steps; k++) {
        fmi2SetReal(c, &in_vr, 1, &in_value);
        if (fmi2DoStep(c, k * h, h, fmi2True) > fmi2Warning) { fprintf(stderr, "doStep failed at %g\n", k * h); return 6; }
    }
    for (int i = 8; i < argc; i++) {
        fmi2ValueReference vr = (fmi2ValueReference)atoi(argv[i]);
        fmi2Real value;
        fmi2GetReal(c, &vr, 1, &value);
        printf("%u %.17g\n", vr, value);
    }
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    if (finalize) finalize();  /* release pythonfmu's interpreter state before exit (docs/third_party.md) */
    return 0;
}
