/* A minimal non-Python FMI 2.0 co-simulation host (what fmusim or a Simulink S-function does):
 * load an extracted FMU's binary, instantiate, set Real inputs, step, print Real outputs,
 * terminate, free, and exit — nothing pythonfmu-specific (no finalizePythonInterpreter, no
 * LD_PRELOAD): the FMU's own binary must make that enough (docs/third_party.md).
 * Used by tests/test_third_party_host.py and benchmarks/clean_exit.py.
 *
 * usage: fmi2_host RUN [-- RUN ...]
 *   RUN = BINARY RESOURCE_URI GUID STOP STEP CYCLES [VR:=VALUE ...] [VR=VALUE ...] [VR ...]
 *   CYCLES  instantiate … free this many times in one process ("2"); letters after the number:
 *           r  the library closed and opened again between cycles ("2r")
 *           d  after the run's last cycle the library is closed and the FMU's extraction (the
 *              folder three levels above BINARY) deleted, as hosts that unpack into a temporary
 *              folder do (fmpy.simulate_fmu, libcosim)
 *           n  no initialisation: instantiate and free only (a host that drops a loaded system
 *              before running it)
 *           f  initialisation is expected to fail: the host then goes on against the standard
 *              (doStep, fmi2GetReal, fmi2Terminate on the failed instance), prints each status as
 *              "after <call>: <status>", and frees the instance
 *   VR:=VALUE  a Real set once before fmi2EnterInitializationMode (a parameter)
 *   VR=VALUE   a Real input set before every step;  VR  a Real output printed after the last step
 * Runs follow one another in one process (load, free, load another FMU).
 * exit: 0 ok, 2 usage, 3 library, 4 instantiation, 5 initialisation, 6 step refused, 7 deletion
 */
#define _XOPEN_SOURCE 700
#include <dlfcn.h>
#include <ftw.h>
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

/* one instance's life; argv[0] is the run's BINARY, argc its word count */
static int cycle(void *lib, char **argv, int argc, int expect_failure, int instantiate_only) {
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
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, argv[2], argv[1], &callbacks, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "instantiation failed\n"); return 4; }
    if (instantiate_only) {
        fmi2FreeInstance(c);
        return 0;
    }
    double stop = atof(argv[3]), h = atof(argv[4]);
    fmi2ValueReference in_vr[64], init_vr[64];
    fmi2Real in_value[64], init_value[64];
    size_t n_in = 0, n_init = 0;
    for (int i = 6; i < argc; i++) {
        char *eq = strchr(argv[i], '=');
        if (!eq) continue;
        if (eq > argv[i] && eq[-1] == ':' && n_init < 64) {
            init_vr[n_init] = (fmi2ValueReference)atoi(argv[i]);
            init_value[n_init++] = atof(eq + 1);
        } else if (n_in < 64) {
            in_vr[n_in] = (fmi2ValueReference)atoi(argv[i]);
            in_value[n_in++] = atof(eq + 1);
        }
    }
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning) return 5;
    if (n_init && fmi2SetReal(c, init_vr, n_init, init_value) > fmi2Warning) return 5;
    if (fmi2EnterInitializationMode(c) > fmi2Warning) return 5;
    fmi2Status exited = fmi2ExitInitializationMode(c);
    if (expect_failure) {
        /* a host that ignores the failure (FMI 2.0 allows only fmi2FreeInstance after fmi2Fatal) */
        fmi2ValueReference vr = 0;
        fmi2Real value = 0.0;
        printf("exitInitializationMode: %d\n", (int)exited);
        printf("after doStep: %d\n", (int)fmi2DoStep(c, 0.0, h, fmi2True));
        printf("after fmi2GetReal: %d\n", (int)fmi2GetReal(c, &vr, 1, &value));
        printf("after fmi2Terminate: %d\n", (int)fmi2Terminate(c));
        fflush(stdout);
        fmi2FreeInstance(c);
        printf("freed\n");
        return 0;
    }
    if (exited > fmi2Warning) return 5;
    long steps = (long)(stop / h + 0.5);
    for (long k = 0; k < steps; k++) {
        if (n_in) fmi2SetReal(c, in_vr, n_in, in_value);
        fmi2Status status = fmi2DoStep(c, k * h, h, fmi2True);
        if (status > fmi2Warning) { fprintf(stderr, "doStep at %g: status %d\n", k * h, (int)status); return 6; }
    }
    for (int i = 6; i < argc; i++) {
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

static int remove_entry(const char *path, const struct stat *info, int flag, struct FTW *ftw) {
    (void)info; (void)flag; (void)ftw;
    return remove(path);
}

/* the extraction of the FMU whose binary is BINARY: BINARY's folder's folder's folder */
static int delete_extraction(const char *binary) {
    char folder[4096];
    snprintf(folder, sizeof folder, "%s", binary);
    for (int up = 0; up < 3; up++) {
        char *slash = strrchr(folder, '/');
        if (!slash) { fprintf(stderr, "%s: not BINARY's path inside an extraction\n", binary); return 7; }
        *slash = '\0';
    }
    if (nftw(folder, remove_entry, 16, FTW_DEPTH | FTW_PHYS) != 0) { perror(folder); return 7; }
    return 0;
}

static int run(char **argv, int argc) {
    if (argc < 6) { fprintf(stderr, "usage: see source\n"); return 2; }
    int cycles = atoi(argv[5]);
    int reload = strchr(argv[5], 'r') != NULL;
    int delete_after = strchr(argv[5], 'd') != NULL;
    int expect_failure = strchr(argv[5], 'f') != NULL;
    int instantiate_only = strchr(argv[5], 'n') != NULL;
    void *lib = NULL;
    for (int k = 0; k < cycles; k++) {
        if (!lib) lib = dlopen(argv[0], RTLD_NOW | RTLD_LOCAL);
        if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
        int code = cycle(lib, argv, argc, expect_failure, instantiate_only);
        if (code) return code;
        if (reload) { dlclose(lib); lib = NULL; }
    }
    if (delete_after) {
        if (lib) dlclose(lib);
        return delete_extraction(argv[0]);
    }
    return 0;   /* the library stays open: the process exit unloads it, as in most hosts */
}

int main(int argc, char **argv) {
    int start = 1;
    while (start < argc) {
        int end = start;
        while (end < argc && strcmp(argv[end], "--") != 0) end++;
        int code = run(argv + start, end - start);
        if (code) return code;
        start = end + 1;
    }
    return start == 1 ? 2 : 0;
}
