/* Every FMI 2.0 co-simulation function called with bad arguments, as a careless or hostile host
 * would: a NULL, freed or foreign component, NULL arrays, value references that are no
 * variable, n = SIZE_MAX and 2^40, the state and derivative calls the FMU does not offer,
 * and fmi2Instantiate with each bad argument. Each call prints "<case> <status>" (an
 * fmi2Instantiate prints "NULL" or "instance") and flushes, so a crash names the case it happened
 * in. After the bad calls the instance must still run: "life <status>" of a normal
 * setup/initialise/step/get. Used by tests/test_fmu_robustness.py (docs/third_party.md).
 *
 * usage: fmi2_bad_calls BINARY RESOURCE_URI GUID STEP REAL_OUTPUT_VR STRING_PARAMETER_VR
 * exit: 0 every case ran (the test judges the statuses), 2 usage, 3 library, 4 no instance
 */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list args;
    (void)env; (void)category;
    va_start(args, message);
    fprintf(stderr, "[%s %d] ", name ? name : "(null)", (int)status);
    vfprintf(stderr, message, args);
    fprintf(stderr, "\n");
    va_end(args);
}

static void show(const char *label, int status) {
    printf("%s %d\n", label, status);
    fflush(stdout);
}

static void show_instance(const char *label, fmi2Component c) {
    printf("%s %s\n", label, c ? "instance" : "NULL");
    fflush(stdout);
}

#define F(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); \
    if (!name) { fprintf(stderr, "missing %s\n", #name); return 3; }

int main(int argc, char **argv) {
    if (argc != 7) { fprintf(stderr, "usage: see source\n"); return 2; }
    const char *uri = argv[2], *guid = argv[3];
    double h = atof(argv[4]);
    fmi2ValueReference out_vr = (fmi2ValueReference)atoi(argv[5]), string_vr = (fmi2ValueReference)atoi(argv[6]);
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
    F(fmi2Instantiate) F(fmi2FreeInstance) F(fmi2SetDebugLogging) F(fmi2SetupExperiment)
    F(fmi2EnterInitializationMode) F(fmi2ExitInitializationMode) F(fmi2Terminate) F(fmi2Reset)
    F(fmi2GetReal) F(fmi2GetInteger) F(fmi2GetBoolean) F(fmi2GetString)
    F(fmi2SetReal) F(fmi2SetInteger) F(fmi2SetBoolean) F(fmi2SetString)
    F(fmi2GetFMUstate) F(fmi2SetFMUstate) F(fmi2FreeFMUstate) F(fmi2SerializedFMUstateSize)
    F(fmi2SerializeFMUstate) F(fmi2DeSerializeFMUstate) F(fmi2GetDirectionalDerivative)
    F(fmi2SetRealInputDerivatives) F(fmi2GetRealOutputDerivatives) F(fmi2DoStep) F(fmi2CancelStep)
    F(fmi2GetStatus) F(fmi2GetRealStatus) F(fmi2GetIntegerStatus) F(fmi2GetBooleanStatus)
    F(fmi2GetStringStatus)

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2CallbackFunctions no_memory = {logger, NULL, NULL, NULL, NULL};
    fmi2Real real_scratch = 0.0;

    /* ---- fmi2Instantiate: each bad argument alone -------------------------------------------- */
    show_instance("instantiate_null_name", fmi2Instantiate(NULL, fmi2CoSimulation, guid, uri, &callbacks, 0, 0));
    show_instance("instantiate_empty_name", fmi2Instantiate("", fmi2CoSimulation, guid, uri, &callbacks, 0, 0));
    show_instance("instantiate_model_exchange", fmi2Instantiate("me", fmi2ModelExchange, guid, uri, &callbacks, 0, 0));
    show_instance("instantiate_unknown_type", fmi2Instantiate("t", (fmi2Type)7, guid, uri, &callbacks, 0, 0));
    show_instance("instantiate_wrong_guid", fmi2Instantiate("g", fmi2CoSimulation, "{not-this-fmu}", uri, &callbacks, 0, 0));
    show_instance("instantiate_null_guid", fmi2Instantiate("g", fmi2CoSimulation, NULL, uri, &callbacks, 0, 0));
    show_instance("instantiate_null_location", fmi2Instantiate("r", fmi2CoSimulation, guid, NULL, &callbacks, 0, 0));
    show_instance("instantiate_missing_location",
                  fmi2Instantiate("r", fmi2CoSimulation, guid, "file:///nonexistent/railcosim/resources", &callbacks, 0, 0));
    show_instance("instantiate_http_location", fmi2Instantiate("r", fmi2CoSimulation, guid, "http://example.org/r", &callbacks, 0, 0));
    show_instance("instantiate_other_host", fmi2Instantiate("r", fmi2CoSimulation, guid, "file://server/share/resources", &callbacks, 0, 0));
    show_instance("instantiate_relative_location", fmi2Instantiate("r", fmi2CoSimulation, guid, "file:resources", &callbacks, 0, 0));
    show_instance("instantiate_nul_escape", fmi2Instantiate("r", fmi2CoSimulation, guid, "file:///tmp%00/resources", &callbacks, 0, 0));
    char long_uri[9000] = "file://";
    for (size_t k = strlen(long_uri); k + 3 < sizeof long_uri; k += 2) strcat(long_uri, "/a");
    show_instance("instantiate_overlong_location", fmi2Instantiate("r", fmi2CoSimulation, guid, long_uri, &callbacks, 0, 0));
    show_instance("instantiate_null_callbacks", fmi2Instantiate("f", fmi2CoSimulation, guid, uri, NULL, 0, 0));

    /* a host without a logger: the slave's messages (a refused step logs one) go nowhere */
    fmi2CallbackFunctions no_logger = {NULL, calloc, free, NULL, NULL};
    fmi2Component quiet = fmi2Instantiate("quiet", fmi2CoSimulation, guid, uri, &no_logger, 0, 1);
    show_instance("instantiate_without_logger", quiet);
    if (quiet) {
        show("doStep_without_logger", fmi2DoStep(quiet, 0.0, h, fmi2True));
        fmi2ValueReference unknown = 0x7ffffff0u;
        show("getReal_without_logger", fmi2GetReal(quiet, &unknown, 1, &real_scratch));
        fmi2FreeInstance(quiet);
    }

    /* a good instance, made by a host that gives no memory functions (the FMU uses none) */
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, guid, uri, &no_memory, 0, 1);
    show_instance("instantiate_without_memory_functions", c);
    if (!c) return 4;
    fmi2Component nobody = NULL;
    fmi2Component foreign = (fmi2Component)&callbacks;   /* not an instance: a host's mix-up */

    /* ---- every function with a NULL and a foreign component --------------------------------- */
    fmi2Component bad[2] = {nobody, foreign};
    const char *which[2] = {"null_component", "foreign_component"};
    fmi2ValueReference vr = out_vr;
    fmi2Real real = 0.0;
    fmi2Integer integer = 0;
    fmi2Boolean boolean = fmi2False;
    fmi2String string = NULL;
    fmi2Status status_value;
    fmi2FMUstate state = NULL;
    size_t size = 0;
    fmi2Byte bytes[16] = {0};
    fmi2Integer order = 1;
    char label[128];
#define ON_BAD(call_name, expression) \
    for (int b = 0; b < 2; b++) { fmi2Component x = bad[b]; \
        snprintf(label, sizeof label, "%s_%s", call_name, which[b]); show(label, (int)(expression)); }
    ON_BAD("setDebugLogging", fmi2SetDebugLogging(x, fmi2True, 0, NULL))
    ON_BAD("setupExperiment", fmi2SetupExperiment(x, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    ON_BAD("enterInitializationMode", fmi2EnterInitializationMode(x))
    ON_BAD("exitInitializationMode", fmi2ExitInitializationMode(x))
    ON_BAD("terminate", fmi2Terminate(x))
    ON_BAD("reset", fmi2Reset(x))
    ON_BAD("getReal", fmi2GetReal(x, &vr, 1, &real))
    ON_BAD("getInteger", fmi2GetInteger(x, &vr, 1, &integer))
    ON_BAD("getBoolean", fmi2GetBoolean(x, &vr, 1, &boolean))
    ON_BAD("getString", fmi2GetString(x, &vr, 1, &string))
    ON_BAD("setReal", fmi2SetReal(x, &vr, 1, &real))
    ON_BAD("setInteger", fmi2SetInteger(x, &vr, 1, &integer))
    ON_BAD("setBoolean", fmi2SetBoolean(x, &vr, 1, &boolean))
    ON_BAD("setString", fmi2SetString(x, &vr, 1, &string))
    ON_BAD("getFMUstate", fmi2GetFMUstate(x, &state))
    ON_BAD("setFMUstate", fmi2SetFMUstate(x, state))
    ON_BAD("freeFMUstate", fmi2FreeFMUstate(x, &state))
    ON_BAD("serializedFMUstateSize", fmi2SerializedFMUstateSize(x, state, &size))
    ON_BAD("serializeFMUstate", fmi2SerializeFMUstate(x, state, bytes, sizeof bytes))
    ON_BAD("deSerializeFMUstate", fmi2DeSerializeFMUstate(x, bytes, sizeof bytes, &state))
    ON_BAD("getDirectionalDerivative", fmi2GetDirectionalDerivative(x, &vr, 1, &vr, 1, &real, &real))
    ON_BAD("setRealInputDerivatives", fmi2SetRealInputDerivatives(x, &vr, 1, &order, &real))
    ON_BAD("getRealOutputDerivatives", fmi2GetRealOutputDerivatives(x, &vr, 1, &order, &real))
    ON_BAD("doStep", fmi2DoStep(x, 0.0, h, fmi2True))
    ON_BAD("cancelStep", fmi2CancelStep(x))
    ON_BAD("getStatus", fmi2GetStatus(x, fmi2DoStepStatus, &status_value))
    ON_BAD("getRealStatus", fmi2GetRealStatus(x, fmi2LastSuccessfulTime, &real))
    ON_BAD("getIntegerStatus", fmi2GetIntegerStatus(x, fmi2DoStepStatus, &integer))
    ON_BAD("getBooleanStatus", fmi2GetBooleanStatus(x, fmi2Terminated, &boolean))
    ON_BAD("getStringStatus", fmi2GetStringStatus(x, fmi2PendingStatus, &string))
    fmi2FreeInstance(nobody);
    show("freeInstance_null", 0);
    fmi2FreeInstance(foreign);
    show("freeInstance_foreign", 0);

    /* ---- the good instance with bad arguments ------------------------------------------------ */
    fmi2String categories[2] = {"logAll", NULL};
    show("setDebugLogging_null_array", fmi2SetDebugLogging(c, fmi2True, 2, NULL));
    show("setDebugLogging_null_category", fmi2SetDebugLogging(c, fmi2True, 2, categories));
    fmi2ValueReference no_variable = 0x7ffffff0u, two[2] = {out_vr, out_vr};
    fmi2Real reals[2];
    show("getReal_null_vr", fmi2GetReal(c, NULL, 1, &real));
    show("getReal_null_values", fmi2GetReal(c, &vr, 1, NULL));
    show("getReal_huge_n", fmi2GetReal(c, two, SIZE_MAX, reals));
    show("getReal_n_2_40", fmi2GetReal(c, two, (size_t)1 << 40, reals));
    show("getReal_no_variable", fmi2GetReal(c, &no_variable, 1, &real));
    show("getInteger_null_values", fmi2GetInteger(c, &vr, 1, NULL));
    show("getInteger_huge_n", fmi2GetInteger(c, two, SIZE_MAX, &integer));
    show("getInteger_no_variable", fmi2GetInteger(c, &no_variable, 1, &integer));
    show("getBoolean_null_vr", fmi2GetBoolean(c, NULL, 3, &boolean));
    show("getBoolean_huge_n", fmi2GetBoolean(c, two, SIZE_MAX, &boolean));
    show("getString_null_values", fmi2GetString(c, &vr, 1, NULL));
    show("getString_huge_n", fmi2GetString(c, two, SIZE_MAX, &string));
    show("getString_no_variable", fmi2GetString(c, &no_variable, 1, &string));
    show("setReal_null_values", fmi2SetReal(c, &vr, 1, NULL));
    show("setReal_huge_n", fmi2SetReal(c, two, SIZE_MAX, reals));
    show("setReal_no_variable", fmi2SetReal(c, &no_variable, 1, &real));
    show("setReal_an_output", fmi2SetReal(c, &vr, 1, &real));
    show("setInteger_null_vr", fmi2SetInteger(c, NULL, 1, &integer));
    show("setInteger_huge_n", fmi2SetInteger(c, two, SIZE_MAX, &integer));
    show("setBoolean_null_values", fmi2SetBoolean(c, &vr, 1, NULL));
    show("setBoolean_huge_n", fmi2SetBoolean(c, two, SIZE_MAX, &boolean));
    fmi2String null_string = NULL;
    show("setString_null_values", fmi2SetString(c, &vr, 1, NULL));
    show("setString_huge_n", fmi2SetString(c, two, SIZE_MAX, &null_string));
    show("setString_no_variable", fmi2SetString(c, &no_variable, 1, &null_string));
    show("setString_null_string", fmi2SetString(c, &string_vr, 1, &null_string));
    show("getFMUstate_null", fmi2GetFMUstate(c, NULL));
    show("getFMUstate", fmi2GetFMUstate(c, &state));
    show("setFMUstate_null", fmi2SetFMUstate(c, NULL));
    show("setFMUstate_foreign", fmi2SetFMUstate(c, (fmi2FMUstate)bytes));
    show("freeFMUstate_null", fmi2FreeFMUstate(c, NULL));
    show("freeFMUstate_foreign", fmi2FreeFMUstate(c, (fmi2FMUstate *)&foreign));
    show("serializedFMUstateSize_null", fmi2SerializedFMUstateSize(c, NULL, NULL));
    show("serializeFMUstate_null", fmi2SerializeFMUstate(c, NULL, NULL, 100));
    show("deSerializeFMUstate_null", fmi2DeSerializeFMUstate(c, NULL, 100, NULL));
    show("deSerializeFMUstate_garbage", fmi2DeSerializeFMUstate(c, bytes, sizeof bytes, &state));
    show("getDirectionalDerivative_null", fmi2GetDirectionalDerivative(c, NULL, 5, NULL, 5, NULL, NULL));
    show("setRealInputDerivatives_null", fmi2SetRealInputDerivatives(c, NULL, 5, NULL, NULL));
    show("getRealOutputDerivatives_null", fmi2GetRealOutputDerivatives(c, NULL, 5, NULL, NULL));
    show("cancelStep", fmi2CancelStep(c));
    show("getStatus_null", fmi2GetStatus(c, fmi2DoStepStatus, NULL));
    show("getStatus_bad_kind", fmi2GetStatus(c, (fmi2StatusKind)99, &status_value));
    show("getRealStatus_null", fmi2GetRealStatus(c, fmi2LastSuccessfulTime, NULL));
    show("getIntegerStatus_null", fmi2GetIntegerStatus(c, fmi2DoStepStatus, NULL));
    show("getBooleanStatus_null", fmi2GetBooleanStatus(c, fmi2Terminated, NULL));
    show("getStringStatus_null", fmi2GetStringStatus(c, fmi2PendingStatus, NULL));
    show("setupExperiment_nan_start", fmi2SetupExperiment(c, fmi2False, 0.0, NAN, fmi2False, 0.0));
    show("doStep_before_initialisation", fmi2DoStep(c, 0.0, h, fmi2True));

    /* ---- the instance is untouched: a normal life --------------------------------------------- */
    fmi2Status life = fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    if (life <= fmi2Warning) life = fmi2EnterInitializationMode(c);
    if (life <= fmi2Warning) life = fmi2ExitInitializationMode(c);
    if (life <= fmi2Warning) show("doStep_nan_step", fmi2DoStep(c, 0.0, NAN, fmi2True));
    if (life <= fmi2Warning) show("doStep_negative_step", fmi2DoStep(c, 0.0, -h, fmi2True));
    if (life <= fmi2Warning) life = fmi2DoStep(c, 0.0, h, fmi2True);
    if (life <= fmi2Warning) life = fmi2GetReal(c, &vr, 1, &real);
    if (life <= fmi2Warning) life = fmi2Terminate(c);
    show("life", (int)life);
    fmi2FreeInstance(c);
    show("freeInstance", 0);
    fmi2FreeInstance(c);
    show("freeInstance_twice", 0);
    show("getReal_after_free", fmi2GetReal(c, &vr, 1, &real));
    return 0;
}
