/* A minimal non-Python FMI 2.0 co-simulation host (what fmusim or a Simulink S-function does):
 * load an extracted FMU's binary, instantiate, set Real inputs, step, print Real outputs,
 * terminate, free, and exit — nothing pythonfmu-specific (no finalizePythonInterpreter, no
 * LD_PRELOAD): the FMU's own binary must make that enough (docs/third_party.md).
 * Used by tests/test_third_party_host.py and benchmarks/clean_exit.py.
 *
 * usage: fmi2_host BINARY RESOURCE_URI GUID STOP STEP CYCLES [VR=VALUE ...] [VR ...]
 *   CYCLES  instantiate … free this many times in one process ("2"), or with the library
 *           closed and opened again between cycles ("2r")
 *   VR=VALUE  a Real input set before every step; VR  a Real output printed after the last step
 * exit: 0 ok, 2 usage, 3 library, 4 instantiation, 5 initialisation, 6 step refused
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list args;
    (void)env; (void)category;
    va_start(args, message);
    fprintf(stderr, "[%s %d] ", name, (int)status);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}

#define LOAD(type, name) type name = (type)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 3; }

static int cycle(void *lib, char **argv, int argc) {
    LOAD(fmi2InstantiateTYPE *, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode)
    LOAD(fmi2SetRealTYPE *, fmi2SetReal)
    LOAD(fmi2GetRealTYPE *, fmi2GetReal)
    LOAD(fmi2DoStepTYPE *, fmi2DoStep)
    LOAD(fmi2TerminateTYPE *, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance)

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, argv[3], argv[2], &callbacks, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "instantiation failed\n"); return 4; }
    double stop = atof(argv[4]), h = atof(argv[5]);
    fmi2ValueReference in_vr[64];
    fmi2Real in_value[64];
    size_t n_in = 0;
    for (int i = 7; i < argc && n_in < 64; i++) {
        char *eq = strchr(argv[i], '=');
        if (eq) { in_vr[n_in] = (fmi2ValueReference)atoi(argv[i]); in_value[n_in++] = atof(eq + 1); }
    }
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning) return 5;
    if (fmi2EnterInitializationMode(c) > fmi2Warning) return 5;
    if (fmi2ExitInitializationMode(c) > fmi2Warning) return 5;
    long steps = (long)(stop / h + 0.5);
    for (long k = 0; k < steps; k++) {
        if (n_in) fmi2SetReal(c, in_vr, n_in, in_value);
        fmi2Status status = fmi2DoStep(c, k * h, h, fmi2True);
        if (status > fmi2Warning) { fprintf(stderr, "doStep at %g: status %d\n", k * h, (int)status); return 6; }
    }
    for (int i = 7; i < argc; i++) {
        if (strchr(argv[i], '=')) continue;
        fmi2ValueReference vr = (fmi2ValueReference)atoi(argv[i]);
        fmi2Real value;
        fmi2GetReal(c, &vr, 1, &value);
        printf("%u %.17g\n", vr, value);
    }
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 7) { fprintf(stderr, "usage: see source\n"); return 2; }
    int cycles = atoi(argv[6]);
    int reload = strchr(argv[6], 'r') != NULL;
    void *lib = NULL;
    for (int k = 0; k < cycles; k++) {
        if (!lib) lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
        if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
        int code = cycle(lib, argv, argc);
        if (code) return code;
        if (reload) { dlclose(lib); lib = NULL; }
    }
    return 0;   /* the library stays open: the process exit unloads it, as in most hosts */
}
