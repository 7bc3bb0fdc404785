/* railcosim's FMI 2.0 binary: a thin forwarder in front of pythonfmu's export library.
 *
 * pythonfmu 0.7.0's binary neither links libpython (every non-Python host had to LD_PRELOAD
 * it) nor leaves a host's process exit alone: it starts CPython from a worker thread and
 * releases it from a library destructor that runs after the C++ runtime already destroyed
 * the state it releases (docs/architecture.md, docs/third_party.md). This library becomes
 * binaries/linux64/<id>.so; pythonfmu's library travels beside it as <id>_pythonfmu.so.
 *
 * At the first fmi2Instantiate it
 *   1. uses the process's Python if there is one (a Python host: fmpy, our orchestrator),
 *      else loads libpython RTLD_GLOBAL (path: $RAILCOSIM_LIBPYTHON, else the build's, from
 *      resources/railcosim_python.txt) and starts it itself with PyConfig, PYTHONHOME and
 *      PYTHONPATH from the environment or else the build's defaults; a Python that cannot
 *      start is an fmi2Instantiate returning NULL with a logged message, not an abort;
 *   2. loads <id>_pythonfmu.so from its own folder (dladdr) and forwards every fmi2 function.
 * pythonfmu then finds Python initialised and never starts or finalises one itself.
 *
 * Arguments: pythonfmu strips "file://" from the resource location and decodes nothing (a folder
 * with a Cyrillic letter, '#', '%' or a space: its slavemodule.txt not found, then a NULL class
 * called, SIGSEGV) and builds std::strings from NULL names (abort). fmi2Instantiate checks every
 * argument first (instantiation_refused): the URI decoded per RFC 3986 to a folder holding
 * slavemodule.txt, a co-simulation request, the FMU's GUID (from resources/railcosim_description.txt,
 * which `railcosim build` writes from the modelDescription: a host need not extract
 * modelDescription.xml); a bad one is NULL with a logged message. pythonfmu gets "file://" and the
 * decoded path. Every other call finds its component in the instance list first (a NULL, freed or
 * foreign one: fmi2Error, a line on stderr) and refuses NULL arrays, n above 2^20 values,
 * the calls the modelDescription does not offer (FMU state, derivatives) with fmi2Error and a
 * logged message (docs/architecture.md, "Forwarding binary").
 *
 * Value references: pythonfmu cannot return fmi2Error (a Python exception is fmi2Fatal). Each
 * instance keeps the valid value references per FMI type, read at fmi2Instantiate from
 * resources/railcosim_value_references.txt under the resource location (written by
 * `railcosim build` from the modelDescription). A get or set naming a reference that is not a
 * variable of its type, or a set of one that cannot be set (an output, a calculated value), is
 * answered fmi2Error with a message through the host's logger and never reaches pythonfmu, so the
 * instance is untouched. Without the file the calls are forwarded unchecked
 * (docs/interfaces.md, "Bad parameters, inputs and calls").
 *
 * Direct values (fmi2_direct.c, with our references to the slave's objects): pythonfmu's
 * wrapper turns every fmi2Get/fmi2Set of Reals, Integers and
 * Booleans into Python lists built value by value (about 0.1 us per value) and a Python call.
 * For an instance whose references are checked here, the forwarder claims the slave's store
 * resolvers at fmi2Instantiate (fmus/fmi/bulk.py, registered by the generated slave script).
 * It keeps each list of value references it sees (a host sends the same lists every step; up
 * to BULK_LISTS per instance), checked and resolved once by the slave to where the values live
 * in its store (the store's address and a first slot, or an array of slots); a get or set of a
 * list it knows is then a copy in C between the host's array and the store, without the GIL
 * and without checking the same references again. fmi2Reset (pythonfmu makes a new slave
 * object with new stores) drops the route and claims it again from the new slave. The host
 * sees the same functions and values. Without the resolvers (another slave, an older FMU, RAILCOSIM_NO_BULK=1 in the
 * environment) or after a resolver failed once (logged as a warning), calls go to pythonfmu as
 * they are (docs/performance.md).
 *
 * After fmi2Fatal: pythonfmu 0.7.0 answers a Python exception with fmi2Fatal after it released its
 * references to the slave, the slave's class and its log queue without forgetting them
 * (PySlaveInstance::handle_py_exception), so any later call on the instance used freed objects
 * (a host calling doStep after fmi2Fatal crashed) and fmi2FreeInstance released them a second
 * time. The forwarder holds one reference of its own to each of the three from fmi2Instantiate
 * on (fmus/fmi/bulk.py `take`); after an fmi2Fatal it answers every call but fmi2FreeInstance
 * with fmi2Error and a logged message without reaching pythonfmu, and hands its references to
 * pythonfmu's second release at fmi2FreeInstance, which then frees the instance cleanly. A
 * fatal fmi2Reset releases the old slave once more: that instance is not freed (a leak, never a
 * crash). Without the references (a slave not registered there) the same: calls refused, not freed.
 *
 * Release: at unload (dlclose of this library or process exit) it empties pythonfmu's
 * interpreter state through pythonfmu's finalizePythonInterpreter, before pythonfmu's own
 * exit-time destructors run, and closes pythonfmu's library if no instance is alive. It never
 * calls Py_FinalizeEx: CPython cannot be re-initialised once numpy was imported, several FMUs
 * may share the interpreter it started, and measured exit behaviour is the same
 * (docs/architecture.md). Build with -DRAILCOSIM_FINALIZE_AT_UNLOAD to finalise anyway.
 */
#define _GNU_SOURCE
#include "fmi2_instance.h"

#include <dlfcn.h>
#include <pthread.h>
#include <ctype.h>
#include <math.h>
#include <strings.h>
#include <unistd.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* marker checked by tests/test_third_party_host.py */
FMI2_Export const char railcosim_forwarder[] = "railcosim fmi2 forwarder 5";

#define SETTINGS_FILE "railcosim_python.txt"
#define VALUE_REFERENCES_FILE "railcosim_value_references.txt"
#define DESCRIPTION_FILE "railcosim_description.txt"

/* ---- the Python C API, resolved at run time (libpython is not a link-time dependency) ---- */
/* (what starting Python needs; the functions that reach the slave's objects: fmi2_direct.c) */
static int (*py_IsInitialized)(void);
static void (*pyConfig_InitPythonConfig)(PyConfig *);
static PyStatus (*pyConfig_SetBytesString)(PyConfig *, wchar_t **, const char *);
static PyStatus (*py_InitializeFromConfig)(const PyConfig *);
static void (*pyConfig_Clear)(PyConfig *);
static int (*pyStatus_Exception)(PyStatus);
static PyThreadState *(*pyEval_SaveThread)(void);
#ifdef RAILCOSIM_FINALIZE_AT_UNLOAD
static void (*pyEval_RestoreThread)(PyThreadState *);
static int (*py_FinalizeEx)(void);
static PyThreadState *main_thread_state;
#endif

/* ---- pythonfmu's library --------------------------------------------------------------- */
#define FMI2_FUNCTIONS(X) \
    X(fmi2SetDebugLogging) X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetupExperiment) \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) \
    X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) \
    X(fmi2SetReal) X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) \
    X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) \
    X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative) \
    X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep) \
    X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus) \
    X(fmi2GetStringStatus)

#define DECLARE(name) static name##TYPE *target_##name;
FMI2_FUNCTIONS(DECLARE)

static void (*target_finalize)(void);  /* pythonfmu's finalizePythonInterpreter */
static void *pythonfmu_library;
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static enum { NOT_LOADED, LOADED, FAILED } state = NOT_LOADED;
static char failure[2048];
static long live_instances;

static void release_at_unload(void);

/* ---- the FMU's folder and its Python settings ------------------------------------------- */
static void own_folder(char *out, size_t size) {
    Dl_info info;
    out[0] = '\0';
    if (dladdr((void *)&own_folder, &info) && info.dli_fname) {
        snprintf(out, size, "%s", info.dli_fname);
        char *slash = strrchr(out, '/');
        if (slash) *slash = '\0'; else snprintf(out, size, ".");
    }
}

static void own_stem(char *out, size_t size) {
    Dl_info info;
    out[0] = '\0';
    if (dladdr((void *)&own_folder, &info) && info.dli_fname) {
        const char *base = strrchr(info.dli_fname, '/');
        snprintf(out, size, "%s", base ? base + 1 : info.dli_fname);
        char *dot = strstr(out, ".so");
        if (dot) *dot = '\0';
    }
}

/* one "KEY=value" line of a file `railcosim build` wrote; 1 if found */
static int key_value(const char *path, const char *key, char *out, size_t size) {
    FILE *file = fopen(path, "r");
    if (!file) return 0;
    char line[8192];
    size_t key_len = strlen(key);
    int found = 0;
    while (!found && fgets(line, sizeof line, file)) {
        if (strncmp(line, key, key_len) == 0 && line[key_len] == '=') {
            line[strcspn(line, "\r\n")] = '\0';
            snprintf(out, size, "%s", line + key_len + 1);
            found = 1;
        }
    }
    fclose(file);
    return found;
}

/* one line of resources/railcosim_python.txt */
static int setting(const char *folder, const char *key, char *out, size_t size) {
    char path[4200];
    snprintf(path, sizeof path, "%s/../../resources/%s", folder, SETTINGS_FILE);
    return key_value(path, key, out, size);
}

static void fail(const char *format, ...) {
    va_list args;
    va_start(args, format);
    vsnprintf(failure, sizeof failure, format, args);
    va_end(args);
    state = FAILED;
}

#define RESOLVE(handle, var, name) \
    if (!(*(void **)&var = dlsym(handle, name))) { fail("libpython has no %s", name); return 0; }

/* Python: the process's own, else the build's libpython started here */
static int ensure_python(const char *folder) {
    void *scope = RTLD_DEFAULT;
    py_IsInitialized = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (py_IsInitialized && py_IsInitialized()) return 1;  /* a Python host: leave it alone */
    if (!py_IsInitialized) {
        char library[4096] = "";
        const char *chosen = getenv("RAILCOSIM_LIBPYTHON");
        if (!chosen || !*chosen) {
            if (!setting(folder, "LIBPYTHON", library, sizeof library)) {
                fail("no libpython: %s/../../resources/%s is missing and RAILCOSIM_LIBPYTHON is not set",
                     folder, SETTINGS_FILE);
                return 0;
            }
            chosen = library;
        }
        scope = dlopen(chosen, RTLD_NOW | RTLD_GLOBAL);  /* never closed */
        if (!scope) {
            fail("cannot load libpython (set RAILCOSIM_LIBPYTHON to the Python the FMU was built with): %s",
                 dlerror());
            return 0;
        }
        RESOLVE(scope, py_IsInitialized, "Py_IsInitialized")
        if (py_IsInitialized()) return 1;
    }
    RESOLVE(scope, pyConfig_InitPythonConfig, "PyConfig_InitPythonConfig")
    RESOLVE(scope, pyConfig_SetBytesString, "PyConfig_SetBytesString")
    RESOLVE(scope, py_InitializeFromConfig, "Py_InitializeFromConfig")
    RESOLVE(scope, pyConfig_Clear, "PyConfig_Clear")
    RESOLVE(scope, pyStatus_Exception, "PyStatus_Exception")
    RESOLVE(scope, pyEval_SaveThread, "PyEval_SaveThread")
#ifdef RAILCOSIM_FINALIZE_AT_UNLOAD
    RESOLVE(scope, pyEval_RestoreThread, "PyEval_RestoreThread")
    RESOLVE(scope, py_FinalizeEx, "Py_FinalizeEx")
#endif

    PyConfig config;
    pyConfig_InitPythonConfig(&config);
    config.install_signal_handlers = 0;  /* the host's signals stay the host's */
    config.parse_argv = 0;
    char value[8192];
    const char *home = getenv("PYTHONHOME");
    PyStatus status = {0};
    if ((!home || !*home) && setting(folder, "PYTHONHOME", value, sizeof value) && *value)
        status = pyConfig_SetBytesString(&config, &config.home, value);
    const char *path = getenv("PYTHONPATH");
    if (!pyStatus_Exception(status) && (!path || !*path) && setting(folder, "PYTHONPATH", value, sizeof value) && *value)
        status = pyConfig_SetBytesString(&config, &config.pythonpath_env, value);
    if (!pyStatus_Exception(status)) status = py_InitializeFromConfig(&config);
    pyConfig_Clear(&config);
    if (pyStatus_Exception(status)) {
        const char *shown = getenv("PYTHONHOME");
        fail("Python could not start (PYTHONHOME %s): %s%s%s", shown && *shown ? shown : "from the FMU's resources",
             status.func ? status.func : "", status.func ? ": " : "", status.err_msg ? status.err_msg : "unknown error");
        return 0;
    }
#ifdef RAILCOSIM_FINALIZE_AT_UNLOAD
    main_thread_state =
#endif
    pyEval_SaveThread();  /* the GIL is free: pythonfmu takes it per call (PyGILState_Ensure) */
    return 1;
}

static int load(void) {
    char folder[4096], stem[512], library[4800];
    own_folder(folder, sizeof folder);
    own_stem(stem, sizeof stem);
    if (!ensure_python(folder)) return 0;
    resolve_python_api();
    snprintf(library, sizeof library, "%s/%s_pythonfmu.so", folder, stem);
    pythonfmu_library = dlopen(library, RTLD_NOW | RTLD_LOCAL);
    if (!pythonfmu_library) { fail("cannot load pythonfmu's library: %s", dlerror()); return 0; }
#define RESOLVE_TARGET(name) *(void **)&target_##name = dlsym(pythonfmu_library, #name);
    FMI2_FUNCTIONS(RESOLVE_TARGET)
    *(void **)&target_finalize = dlsym(pythonfmu_library, "finalizePythonInterpreter");
    if (!target_fmi2Instantiate) { fail("%s exports no fmi2Instantiate", library); return 0; }
    /* registered after pythonfmu's own exit-time destructors, so it runs before them */
    atexit(release_at_unload);
    state = LOADED;
    return 1;
}

static void release_at_unload(void) {
    pthread_mutex_lock(&lock);
    if (state == LOADED) {
        if (target_finalize) target_finalize();  /* pythonfmu's global state emptied while it is valid */
#ifdef RAILCOSIM_FINALIZE_AT_UNLOAD
        if (main_thread_state && live_instances == 0) {
            pyEval_RestoreThread(main_thread_state);
            py_FinalizeEx();
            main_thread_state = NULL;
        }
#endif
        if (live_instances == 0) {
            dlclose(pythonfmu_library);
            pythonfmu_library = NULL;
            state = NOT_LOADED;
        }
    }
    pthread_mutex_unlock(&lock);
}

/* ---- fmi2Instantiate's arguments, checked before pythonfmu sees any of them --------------- */
#define RESOURCE_MODULE_FILE "slavemodule.txt"   /* what pythonfmu reads first from the resources */

/* the local path of a file: URI per RFC 3986 (file:///a%20b, file:/a, file://localhost/a; the
 * scheme and "localhost" in any case), every %XX decoded; 1, or 0 with *why: not a local file:
 * URI, a %00, or longer than `size`. A '%' without two hex digits after it, '#' and '?' are taken
 * as part of the path: a host that does not encode (the spec asks for a URI, some hosts pass
 * "file://" and the path as it is) still names its folder. */
static int uri_folder(const char *uri, char *out, size_t size, const char **why) {
    if (strncasecmp(uri, "file:", 5) != 0) { *why = "not a file: URI"; return 0; }
    const char *p = uri + 5;
    if (strncasecmp(p, "//localhost/", 12) == 0) p += 11;
    else if (strncmp(p, "///", 3) == 0) p += 2;
    else if (p[0] == '/' && p[1] == '/') { *why = "a file: URI of another host"; return 0; }
    if (p[0] != '/') { *why = "not an absolute path"; return 0; }
    size_t k = 0;
    for (; *p; p++) {
        if (k + 1 >= size) { *why = "the path is too long"; return 0; }
        if (p[0] == '%' && isxdigit((unsigned char)p[1]) && isxdigit((unsigned char)p[2])) {
            char hex[3] = {p[1], p[2], 0};
            out[k] = (char)strtol(hex, NULL, 16);
            if (!out[k++]) { *why = "the path contains %00"; return 0; }
            p += 2;
        } else {
            out[k++] = *p;
        }
    }
    out[k] = '\0';
    while (k > 1 && out[k - 1] == '/') out[--k] = '\0';
    return 1;
}

static int has_module_file(const char *folder) {
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", folder, RESOURCE_MODULE_FILE);
    return access(path, R_OK) == 0;
}

/* the resources folder the host names: the decoded path, else (a host that does not encode and a
 * folder named like "%41") the path as written; 1, or 0 with a message in why */
static int resource_folder(const char *uri, char *out, size_t size, char *why, size_t why_size) {
    const char *problem = NULL;
    if (!uri) { snprintf(why, why_size, "no resource location (NULL)"); return 0; }
    if (!uri_folder(uri, out, size, &problem)) {
        snprintf(why, why_size, "resource location \"%.300s\": %s", uri, problem);
        return 0;
    }
    if (has_module_file(out)) return 1;
    const char *literal = strncasecmp(uri, "file://localhost/", 17) == 0 ? uri + 16 : uri + (strncmp(uri + 5, "///", 3) == 0 ? 7 : 5);
    if (strchr(literal, '%') && strlen(literal) < size && has_module_file(literal)) {
        snprintf(out, size, "%s", literal);
        return 1;
    }
    snprintf(why, why_size, "resource location \"%.300s\": %.300s/%s cannot be read (not this FMU's extracted resources folder)",
             uri, out, RESOURCE_MODULE_FILE);
    return 0;
}

static int description_number(const char *path, const char *key) {
    char value[32];
    return key_value(path, key, value, sizeof value) ? atoi(value) : 0;
}

/* 1, or 0 with a message in why */
static int read_description(const char *resources, Description *out, char *why, size_t why_size) {
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", resources, DESCRIPTION_FILE);
    memset(out, 0, sizeof *out);
    if (!key_value(path, "guid", out->guid, sizeof out->guid)) {
        snprintf(why, why_size, "%.300s has no guid line (an FMU built without it?)", path);
        return 0;
    }
    out->co_simulation = description_number(path, "CoSimulation");
    out->fmu_state = description_number(path, "canGetAndSetFMUstate");
    out->serialize = description_number(path, "canSerializeFMUstate");
    out->directional = description_number(path, "providesDirectionalDerivative");
    out->interpolate_inputs = description_number(path, "canInterpolateInputs");
    out->output_derivatives = description_number(path, "maxOutputDerivativeOrder") > 0;
    return 1;
}

/* the reason fmi2Instantiate must refuse these arguments (into why), or 0 when they are good;
 * *description and the decoded resources folder are filled in */
static int instantiation_refused(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID, fmi2String location,
                                 char *folder, size_t folder_size, Description *description, char *why, size_t why_size) {
    if (!instanceName || !*instanceName) {
        snprintf(why, why_size, "fmi2Instantiate refused: the instance name is %s (FMI 2.0 asks for a non-empty name)",
                 instanceName ? "empty" : "NULL");
        return 1;
    }
    char problem[1200];
    if (!resource_folder(location, folder, folder_size, problem, sizeof problem) ||
        !read_description(folder, description, problem, sizeof problem)) {
        snprintf(why, why_size, "fmi2Instantiate refused: %s", problem);
        return 1;
    }
    if (fmuType != fmi2CoSimulation || !description->co_simulation) {
        snprintf(why, why_size, "fmi2Instantiate refused: %s",
                 fmuType == fmi2ModelExchange ? "ModelExchange requested; this FMU is for co-simulation only" :
                 fmuType != fmi2CoSimulation ? "an unknown FMU type requested; this FMU is for co-simulation only" :
                 "the FMU's description has no CoSimulation interface");
        return 1;
    }
    if (!fmuGUID || strcmp(fmuGUID, description->guid) != 0) {
        snprintf(why, why_size, "fmi2Instantiate refused: GUID %s%.200s%s is not this FMU's %s (a modelDescription.xml of "
                 "another FMU or build?)", fmuGUID ? "\"" : "", fmuGUID ? fmuGUID : "NULL", fmuGUID ? "\"" : "",
                 description->guid);
        return 1;
    }
    return 0;
}

/* ---- per instance: its name, the host's callbacks and its valid value references ---------- */
/* (the record itself: fmi2_instance.h; the checks of a get or set: fmi2_checks.c) */

static Instance *instances;            /* a short list, guarded by table_lock */
static pthread_mutex_t table_lock = PTHREAD_MUTEX_INITIALIZER;

static int bitmap_add(Bitmap *map, unsigned long vr) {
    if (vr >= map->size) {
        size_t bytes = vr / 8 + 1, old = map->size / 8;
        if (bytes < 2 * old) bytes = 2 * old;
        unsigned char *grown = realloc(map->bits, bytes);
        if (!grown) return 0;
        memset(grown + old, 0, bytes - old);
        map->bits = grown;
        map->size = bytes * 8;
    }
    map->bits[vr / 8] |= (unsigned char)(1u << (vr % 8));
    return 1;
}

static void free_instance_entry(Instance *entry) {
    drop_bulk(entry);
    release_held(entry);
    for (int t = 0; t < TYPES; t++) { free(entry->valid[t].bits); free(entry->settable[t].bits); }
    free(entry);
}

/* resources/railcosim_value_references.txt: whitespace-separated words; a word naming a table
 * ("Real", "Real:set", ...) makes the numbers after it that table's value references; '#'
 * starts a comment line. Returns 0 if the file cannot be read. */
static int read_value_references(const char *folder, Instance *entry) {
    char path[4400];
    snprintf(path, sizeof path, "%s/%s", folder, VALUE_REFERENCES_FILE);
    FILE *file = fopen(path, "r");
    if (!file) return 0;
    Bitmap *current = NULL;
    char word[64];
    int c = getc(file), ok = 1;
    while (ok && c != EOF) {
        if (isspace(c)) { c = getc(file); continue; }
        if (c == '#') { while (c != EOF && c != '\n') c = getc(file); continue; }
        size_t len = 0;
        while (c != EOF && !isspace(c)) { if (len + 1 < sizeof word) word[len++] = (char)c; c = getc(file); }
        word[len] = '\0';
        if (isdigit((unsigned char)word[0])) {
            if (current) ok = bitmap_add(current, strtoul(word, NULL, 10));
            continue;
        }
        current = NULL;
        for (int t = 0; t < TYPES; t++) {
            size_t n = strlen(type_names[t]);
            if (strncmp(word, type_names[t], n) == 0)
                current = word[n] == '\0' ? &entry->valid[t] : strcmp(word + n, ":set") == 0 ? &entry->settable[t] : NULL;
            if (current) break;
        }
    }
    fclose(file);
    return ok;
}

static Instance *find_instance(fmi2Component c) {
    pthread_mutex_lock(&table_lock);
    Instance *entry = instances;
    while (entry && entry->component != c) entry = entry->next;
    pthread_mutex_unlock(&table_lock);
    return entry;  /* lives until fmi2FreeInstance of c, which the host does not call meanwhile */
}

/* an instance that returned fmi2Fatal: the call refused with fmi2Error and a logged message (1), or 0 */
static int refused_after_fatal(const Instance *entry, const char *call) {
    if (!entry->fatal) return 0;
    char text[400];
    snprintf(text, sizeof text, "%s: %s refused: the instance returned fmi2Fatal before (FMI 2.0 allows no "
             "further call; fmi2FreeInstance still releases it)", entry->name, call);
    log_error(entry, text);
    return 1;
}

/* pythonfmu's answer, noted when fatal (`reset`: the answer of fmi2Reset) */
static fmi2Status noted(Instance *entry, fmi2Status status, int reset) {
    if (status == fmi2Fatal && !entry->fatal) {
        entry->fatal = 1;
        if (reset || !entry->held[0]) entry->leak = 1;
        else for (int k = 0; k < 3; k++) entry->held[k] = NULL;  /* pythonfmu's second release takes them */
    }
    return status;
}

/* the instance `c` names, or NULL for a NULL, freed or foreign component (refused with fmi2Error:
 * no logger is known for it, so the line goes to stderr) */
static Instance *known(fmi2Component c, const char *call) {
    Instance *entry = c ? find_instance(c) : NULL;
    if (!entry)
        fprintf(stderr, "railcosim FMU: %s refused: %s\n", call,
                c ? "the component is not a live instance of this FMU (freed, or another FMU's)" : "the component is NULL");
    return entry;
}

/* a call refused for its arguments: fmi2Error with `why` logged */
static fmi2Status refused(const Instance *entry, const char *call, const char *why) {
    char text[600];
    snprintf(text, sizeof text, "%s: %s refused: %s", entry->name, call, why);
    log_error(entry, text);
    return fmi2Error;
}

/* fmi2SetDebugLogging's categories: n of them, none NULL, or why not */
static const char *bad_categories(size_t n, const fmi2String categories[]) {
    if (n && !categories) return "categories counted and no array given";
    for (size_t i = 0; i < n; i++)
        if (!categories[i]) return "a category is NULL";
    return NULL;
}

/* fmi2SetupExperiment's times: the slave answers a non-finite start with fmi2Fatal (the instance
 * lost); a bad argument is refused here with fmi2Error instead, the instance untouched */
static const char *bad_experiment(fmi2Boolean tolerance_defined, fmi2Real tolerance, fmi2Real start,
                                  fmi2Boolean stop_defined, fmi2Real stop) {
    if (!isfinite(start)) return "the start time is not finite";
    if (stop_defined && (isnan(stop) || stop < start)) return "the stop time is NaN or before the start time";
    if (tolerance_defined && !(tolerance > 0.0)) return "the tolerance is not positive";
    return NULL;
}

static const char *bad_status_kind(fmi2StatusKind kind, const void *value) {
    if (!value) return "no value pointer";
    if (kind < fmi2DoStepStatus || kind > fmi2Terminated) return "not an fmi2StatusKind";
    return NULL;
}

/* ---- the FMI functions -------------------------------------------------------------------- */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

/* a refused instantiation, logged through the host's logger (else stderr) */
static void log_refusal(const fmi2CallbackFunctions *functions, fmi2String instanceName, fmi2Status status,
                        const char *text) {
    const char *name = instanceName && *instanceName ? instanceName : "FMU";
    if (functions && functions->logger)
        functions->logger(functions->componentEnvironment, name, status, status == fmi2Fatal ? "error" : "logStatusError",
                          "%s", text);
    else
        fprintf(stderr, "%s: %s\n", name, text);
}

/* the logger of a host that gives none (pythonfmu calls it unchecked) */
static void silent_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                          fmi2String message, ...) {
    (void)env; (void)name; (void)status; (void)category; (void)message;
}

/* the arguments checked first (instantiation_refused); pythonfmu gets the decoded resources folder
 * as "file://<path>" (it strips those seven characters and decodes nothing) and a copy of the
 * callbacks that lives as long as the instance */
fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    char folder[4096], why[2048];
    Description description;
    if (!functions) {
        log_refusal(NULL, instanceName, fmi2Error, "fmi2Instantiate refused: no callback functions (NULL)");
        return NULL;
    }
    if (instantiation_refused(instanceName, fmuType, fmuGUID, fmuResourceLocation, folder, sizeof folder,
                              &description, why, sizeof why)) {
        log_refusal(functions, instanceName, fmi2Error, why);
        return NULL;
    }
    pthread_mutex_lock(&lock);
    int ready = state == LOADED || (state == NOT_LOADED && load());
    pthread_mutex_unlock(&lock);
    if (!ready) {
        log_refusal(functions, instanceName, fmi2Fatal, failure);
        return NULL;
    }
    Instance *entry = calloc(1, sizeof *entry);
    size_t location_size = strlen(folder) + sizeof "file://";
    char *location = malloc(location_size);
    if (!entry || !location) {
        free(entry);
        free(location);
        log_refusal(functions, instanceName, fmi2Error, "fmi2Instantiate refused: out of memory");
        return NULL;
    }
    snprintf(location, location_size, "file://%s", folder);
    snprintf(entry->name, sizeof entry->name, "%s", instanceName);
    entry->callbacks = *functions;
    if (!entry->callbacks.logger) entry->callbacks.logger = silent_logger;
    /* the modelDescription says canNotUseMemoryManagementFunctions: a host may leave them out */
    if (!entry->callbacks.allocateMemory || !entry->callbacks.freeMemory) {
        entry->callbacks.allocateMemory = calloc;
        entry->callbacks.freeMemory = free;
    }
    entry->description = description;
    fmi2Component component = target_fmi2Instantiate(instanceName, fmuType, fmuGUID, location, &entry->callbacks,
                                                     visible, loggingOn);
    free(location);
    if (!component) {
        free(entry);
        return NULL;
    }
    pthread_mutex_lock(&lock);
    live_instances++;
    pthread_mutex_unlock(&lock);
    entry->component = component;
    entry->checked = read_value_references(folder, entry);
    claim_instance(entry);
    pthread_mutex_lock(&table_lock);
    entry->next = instances;
    instances = entry;
    pthread_mutex_unlock(&table_lock);
    return component;
}

/* a component that is not a live instance of this FMU (NULL, freed twice, another FMU's) is
 * left alone with a line on stderr */
void fmi2FreeInstance(fmi2Component c) {
    pthread_mutex_lock(&table_lock);
    Instance **link = &instances;
    while (c && *link && (*link)->component != c) link = &(*link)->next;
    Instance *entry = c ? *link : NULL;
    if (entry) *link = entry->next;
    pthread_mutex_unlock(&table_lock);
    if (!entry) {
        known(c, "fmi2FreeInstance");
        return;
    }
    if (!entry->leak) target_fmi2FreeInstance(c);  /* (its references are released in there) */
    if (entry->leak) for (int k = 0; k < 3; k++) entry->held[k] = NULL;  /* kept: the instance is never freed */
    free_instance_entry(entry);
    pthread_mutex_lock(&lock);
    live_instances--;
    pthread_mutex_unlock(&lock);
}

/* every call: the component one of ours (known), not after fmi2Fatal, its arguments good
 * (`bad`: why not, or NULL), then pythonfmu's function */
#define FORWARD(name, params, args, bad) \
    fmi2Status name params { \
        Instance *entry = known(c, #name); \
        if (!entry || !target_##name || refused_after_fatal(entry, #name)) return fmi2Error; \
        const char *why = (bad); \
        if (why) return refused(entry, #name, why); \
        return noted(entry, target_##name args, 0); \
    }
#define STATE_CALLS(entry) \
    (!(entry)->description.fmu_state ? "the FMU cannot get or set its state (canGetAndSetFMUstate=\"false\")" : NULL)
#define SERIALIZE_CALLS(entry) \
    (!(entry)->description.serialize ? "the FMU cannot serialize its state (canSerializeFMUstate=\"false\")" : NULL)

FORWARD(fmi2SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]),
        (c, on, n, categories), bad_categories(n, categories))
FORWARD(fmi2SetupExperiment, (fmi2Component c, fmi2Boolean tolerance_defined, fmi2Real tolerance,
        fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop),
        (c, tolerance_defined, tolerance, start, stop_defined, stop),
        bad_experiment(tolerance_defined, tolerance, start, stop_defined, stop))
FORWARD(fmi2EnterInitializationMode, (fmi2Component c), (c), NULL)
FORWARD(fmi2ExitInitializationMode, (fmi2Component c), (c), NULL)
FORWARD(fmi2Terminate, (fmi2Component c), (c), NULL)

/* pythonfmu's reset makes a new slave object (with new stores): the direct route is dropped
 * before it and claimed again from the new slave after it */
fmi2Status fmi2Reset(fmi2Component c) {
    Instance *entry = known(c, "fmi2Reset");
    if (!entry || !target_fmi2Reset || refused_after_fatal(entry, "fmi2Reset")) return fmi2Error;
    drop_bulk(entry);
    fmi2Status status = noted(entry, target_fmi2Reset(c), 1);
    if (status <= fmi2Warning) {
        release_held(entry);         /* the old slave's: pythonfmu made a new one */
        claim_instance(entry);
    }
    return status;
}
/* get and set: every value reference checked first (check_references); the number types
 * straight between the host's array and the slave's store when the instance allows it */
#define CHECKED(name, type, setting, params) \
    fmi2Status name params { \
        fmi2Status status; \
        Instance *entry = known(c, #name); \
        if (!entry || !target_##name || refused_after_fatal(entry, #name)) return fmi2Error; \
        if (type < DIRECT_TYPES && direct_values(entry, type, setting, vr, n, (void *)value, &status)) return status; \
        if (check_references(entry, vr, n, value, type, setting) != fmi2OK) return fmi2Error; \
        return noted(entry, target_##name(c, vr, n, value), 0); \
    }

CHECKED(fmi2GetReal, REAL, 0, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]))
CHECKED(fmi2GetInteger, INTEGER, 0, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]))
CHECKED(fmi2GetBoolean, BOOLEAN, 0, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]))
CHECKED(fmi2GetString, STRING, 0, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]))
CHECKED(fmi2SetReal, REAL, 1, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]))
CHECKED(fmi2SetInteger, INTEGER, 1, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]))
CHECKED(fmi2SetBoolean, BOOLEAN, 1, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]))
CHECKED(fmi2SetString, STRING, 1, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]))
FORWARD(fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s),
        STATE_CALLS(entry) ? STATE_CALLS(entry) : !s ? "no FMUstate pointer" : NULL)
FORWARD(fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s),
        STATE_CALLS(entry) ? STATE_CALLS(entry) : !s ? "no FMUstate (NULL)" : NULL)
FORWARD(fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s),
        STATE_CALLS(entry) ? STATE_CALLS(entry) : !s ? "no FMUstate pointer" : NULL)
FORWARD(fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *size), (c, s, size),
        SERIALIZE_CALLS(entry) ? SERIALIZE_CALLS(entry) : !s || !size ? "no FMUstate or no size pointer" : NULL)
FORWARD(fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size), (c, s, bytes, size),
        SERIALIZE_CALLS(entry) ? SERIALIZE_CALLS(entry) : !s || (size && !bytes) ? "no FMUstate or no byte array" : NULL)
FORWARD(fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s), (c, bytes, size, s),
        SERIALIZE_CALLS(entry) ? SERIALIZE_CALLS(entry) : !s || (size && !bytes) ? "no FMUstate pointer or no byte array" : NULL)
FORWARD(fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference unknown[], size_t n_unknown,
        const fmi2ValueReference known_vr[], size_t n_known, const fmi2Real dv_known[], fmi2Real dv_unknown[]),
        (c, unknown, n_unknown, known_vr, n_known, dv_known, dv_unknown),
        !entry->description.directional ? "the FMU provides no directional derivatives (providesDirectionalDerivative)" :
        (n_unknown && (!unknown || !dv_unknown)) || (n_known && (!known_vr || !dv_known)) ? "an array is NULL" : NULL)
FORWARD(fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
        const fmi2Integer order[], const fmi2Real value[]), (c, vr, n, order, value),
        !entry->description.interpolate_inputs ? "the FMU does not interpolate inputs (canInterpolateInputs=\"false\")" :
        n && (!vr || !order || !value) ? "an array is NULL" : NULL)
FORWARD(fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
        const fmi2Integer order[], fmi2Real value[]), (c, vr, n, order, value),
        !entry->description.output_derivatives ? "the FMU provides no output derivatives (maxOutputDerivativeOrder)" :
        n && (!vr || !order || !value) ? "an array is NULL" : NULL)
FORWARD(fmi2DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior_state), (c, t, h, no_prior_state), NULL)
/* fmi2DoStep never returns fmi2Pending (canRunAsynchronuously is false): no step to cancel */
FORWARD(fmi2CancelStep, (fmi2Component c), (c), "no step is pending (the FMU never returns fmi2Pending)")
FORWARD(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Status *value), (c, kind, value),
        bad_status_kind(kind, value))
FORWARD(fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Real *value), (c, kind, value),
        bad_status_kind(kind, value))
FORWARD(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Integer *value), (c, kind, value),
        bad_status_kind(kind, value))
FORWARD(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *value), (c, kind, value),
        bad_status_kind(kind, value))
FORWARD(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind kind, fmi2String *value), (c, kind, value),
        bad_status_kind(kind, value))
