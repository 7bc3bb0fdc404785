/* railcosim's FMI 2.0 binary, its second part: the slave's objects reached through the Python
 * C API once Python runs (fmi2_forward.c starts it and forwards the calls; see its top comment,
 * "Direct values" and "After fmi2Fatal"): our references to what pythonfmu holds of each slave,
 * and the direct route of Real, Integer and Boolean values between the host's arrays and the
 * slave's stores (fmus/fmi/bulk.py resolves where the values live). */
#define _GNU_SOURCE
#include "fmi2_instance.h"

#include <dlfcn.h>
#include <stdlib.h>
#include <string.h>

/* the Python functions the instance references and the direct route need (resolved once Python
 * runs; all NULL: no references held, no direct route) */
static PyGILState_STATE (*pyGILState_Ensure)(void);
static void (*pyGILState_Release)(PyGILState_STATE);
static PyObject *(*pyImport_ImportModule)(const char *);
static PyObject *(*pyObject_CallMethod)(PyObject *, const char *, const char *, ...);
static PyObject *(*pyObject_CallFunctionObjArgs)(PyObject *, ...);
static PyObject *(*pyMemoryView_FromMemory)(char *, Py_ssize_t, int);
static PyObject *(*pyTuple_GetItem)(PyObject *, Py_ssize_t);
static Py_ssize_t (*pyTuple_Size)(PyObject *);
static void *(*pyLong_AsVoidPtr)(PyObject *);
static Py_ssize_t (*pyLong_AsSsize_t)(PyObject *);
static PyObject *(*pyErr_Occurred)(void);
static void (*py_IncRef)(PyObject *);
static void (*py_DecRef)(PyObject *);
static void (*pyErr_Clear)(void);
static int python_api;                 /* the functions above are resolved */
static int bulk_enabled;

/* the Python functions the instance references and bulk access need, from the process's Python
 * (ours is RTLD_GLOBAL) */
void resolve_python_api(void) {
#define RESOLVE_BULK(var, name) if (!(*(void **)&var = dlsym(RTLD_DEFAULT, name))) return;
    RESOLVE_BULK(pyGILState_Ensure, "PyGILState_Ensure")
    RESOLVE_BULK(pyGILState_Release, "PyGILState_Release")
    RESOLVE_BULK(pyImport_ImportModule, "PyImport_ImportModule")
    RESOLVE_BULK(pyObject_CallMethod, "PyObject_CallMethod")
    RESOLVE_BULK(pyObject_CallFunctionObjArgs, "PyObject_CallFunctionObjArgs")
    RESOLVE_BULK(pyMemoryView_FromMemory, "PyMemoryView_FromMemory")
    RESOLVE_BULK(pyTuple_GetItem, "PyTuple_GetItem")
    RESOLVE_BULK(pyTuple_Size, "PyTuple_Size")
    RESOLVE_BULK(pyLong_AsVoidPtr, "PyLong_AsVoidPtr")
    RESOLVE_BULK(pyLong_AsSsize_t, "PyLong_AsSsize_t")
    RESOLVE_BULK(pyErr_Occurred, "PyErr_Occurred")
    RESOLVE_BULK(py_IncRef, "Py_IncRef")
    RESOLVE_BULK(py_DecRef, "Py_DecRef")
    RESOLVE_BULK(pyErr_Clear, "PyErr_Clear")
    python_api = 1;
    const char *off = getenv("RAILCOSIM_NO_BULK");
    bulk_enabled = !(off && *off && strcmp(off, "0") != 0);
}

/* the resolvers and lists released (with the GIL held, or taken here) */
static void release_bulk(Instance *entry) {
    for (int t = 0; t < DIRECT_TYPES; t++) {
        py_DecRef(entry->resolvers[t]);
        entry->resolvers[t] = NULL;
    }
    for (int k = 0; k < entry->list_count; k++) free(entry->lists[k].vr);
    entry->list_count = 0;
    entry->direct = 0;
}

void drop_bulk(Instance *entry) {
    if (!entry->direct) return;
    PyGILState_STATE gil = pyGILState_Ensure();
    release_bulk(entry);
    pyGILState_Release(gil);
}

/* our references to what pythonfmu holds of the slave, released (taking the GIL) */
void release_held(Instance *entry) {
    if (!entry->held[0] && !entry->held[1] && !entry->held[2]) return;
    PyGILState_STATE gil = pyGILState_Ensure();
    for (int k = 0; k < 3; k++) {
        py_DecRef(entry->held[k]);
        entry->held[k] = NULL;
    }
    pyGILState_Release(gil);
}

/* right after pythonfmu created the slave (fmus/fmi/bulk.py `take`): our references to what pythonfmu
 * holds of it, and its store resolvers when the instance may use them */
void claim_instance(Instance *entry) {
    if (!python_api) return;
    int want_resolvers = bulk_enabled && entry->checked;
    PyGILState_STATE gil = pyGILState_Ensure();
    PyObject *module = pyImport_ImportModule("fmus.fmi.bulk");
    PyObject *taken = module ? pyObject_CallMethod(module, "take", "si", entry->name, want_resolvers) : NULL;
    Py_ssize_t size = taken ? pyTuple_Size(taken) : -1;
    if (size == 3 || size == 3 + DIRECT_TYPES) {
        for (int k = 0; k < 3; k++) {
            entry->held[k] = pyTuple_GetItem(taken, k);
            py_IncRef(entry->held[k]);
        }
        if (want_resolvers && size == 3 + DIRECT_TYPES) {
            for (int t = 0; t < DIRECT_TYPES; t++) {
                entry->resolvers[t] = pyTuple_GetItem(taken, 3 + t);
                py_IncRef(entry->resolvers[t]);
            }
            entry->direct = 1;
        }
    }
    pyErr_Clear();  /* not one of ours, or an older build: pythonfmu's path, no references held */
    py_DecRef(taken);
    py_DecRef(module);
    pyGILState_Release(gil);
}

/* the list of value references of `type` the instance checked (for a get, or for a set) and
 * resolved before, or -1 (no GIL needed: a host does not call one instance from two threads at
 * once) */
static int known_list(const Instance *entry, int type, int setting, const fmi2ValueReference vr[], size_t n) {
    for (int k = 0; k < entry->list_count; k++)
        if (entry->lists[k].type == type && entry->lists[k].setting == setting && entry->lists[k].n == n &&
            memcmp(entry->lists[k].vr, vr, n * sizeof *vr) == 0)
            return k;
    return -1;
}

/* a checked list resolved by the slave and kept: its index, or -1 when the instance keeps
 * BULK_LISTS lists already or the resolver failed (its resolvers are then dropped with a
 * warning, for this and later calls) */
static int resolve_list(Instance *entry, int type, int setting, const fmi2ValueReference vr[], size_t n) {
    if (entry->list_count == BULK_LISTS) return -1;
    fmi2ValueReference *copy = malloc(n * sizeof *vr);
    if (!copy) return -1;
    memcpy(copy, vr, n * sizeof *vr);
    PyGILState_STATE gil = pyGILState_Ensure();
    PyObject *refs = pyMemoryView_FromMemory((char *)copy, (Py_ssize_t)(n * sizeof *vr), PyBUF_READ);
    PyObject *where = refs ? pyObject_CallFunctionObjArgs(entry->resolvers[type], refs, NULL) : NULL;
    char *store = NULL;
    Py_ssize_t first = 0;
    const int64_t *slots = NULL;
    if (where && pyTuple_Size(where) == 3) {
        store = pyLong_AsVoidPtr(pyTuple_GetItem(where, 0));
        first = pyLong_AsSsize_t(pyTuple_GetItem(where, 1));
        slots = pyLong_AsVoidPtr(pyTuple_GetItem(where, 2));
    }
    int failed = !store || pyErr_Occurred() != NULL;
    py_DecRef(where);
    py_DecRef(refs);
    if (failed) {
        pyErr_Clear();
        release_bulk(entry);
    }
    pyGILState_Release(gil);
    if (failed) {
        free(copy);
        if (entry->callbacks.logger)
            entry->callbacks.logger(entry->callbacks.componentEnvironment, entry->name, fmi2Warning,
                                    "logStatusWarning", "direct value access failed; values go through pythonfmu from now on");
        return -1;
    }
    int k = entry->list_count++;
    entry->lists[k].type = type;
    entry->lists[k].setting = setting;
    entry->lists[k].n = n;
    entry->lists[k].vr = copy;
    entry->lists[k].store = store;
    entry->lists[k].first = first;
    entry->lists[k].slots = slots;
    return k;
}

#define COPY_VALUES(store_type, get_expression, set_expression) { \
        store_type *base = (store_type *)list->store + list->first; \
        for (size_t i = 0; i < list->n; i++) { \
            store_type *slot = list->slots ? (store_type *)list->store + list->slots[i] : base + i; \
            if (setting) { set_expression; } else { get_expression; } \
        } \
    }

/* a get or set of `type` straight between the host's array and the slave's store: 1 done
 * (*status the answer: fmi2Error for a reference the checks refuse), 0 not (pythonfmu's route) */
int direct_values(Instance *entry, int type, int setting, const fmi2ValueReference vr[], size_t n,
                  void *value, fmi2Status *status) {
    if (!bulk_enabled || n == 0 || !vr || !value || !entry->direct) return 0;
    int k = known_list(entry, type, setting, vr, n);
    if (k < 0) {
        if (check_references(entry, vr, n, value, type, setting) != fmi2OK) {
            *status = fmi2Error;
            return 1;
        }
        if ((k = resolve_list(entry, type, setting, vr, n)) < 0) return 0;
    }
    const DirectList *list = &entry->lists[k];
    if (type == REAL && !list->slots) {
        double *run = (double *)list->store + list->first;
        if (setting) memcpy(run, value, n * sizeof *run);
        else memcpy(value, run, n * sizeof *run);
    } else if (type == REAL) {
        fmi2Real *values = value;
        COPY_VALUES(double, values[i] = *slot, *slot = values[i])
    } else if (type == INTEGER) {
        fmi2Integer *values = value;
        COPY_VALUES(int64_t, values[i] = (fmi2Integer)*slot, *slot = values[i])
    } else {
        fmi2Boolean *values = value;
        COPY_VALUES(unsigned char, values[i] = *slot ? fmi2True : fmi2False, *slot = values[i] != fmi2False)
    }
    *status = fmi2OK;
    return 1;
}
