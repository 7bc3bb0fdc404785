/* What the C files of railcosim's FMI 2.0 binary share: the per-instance record and the
 * functions one calls in another. They call one way: fmi2_forward.c (the forwarder) calls
 * fmi2_direct.c (the slave's objects through the Python C API) and fmi2_checks.c (a get or set
 * checked against the value references); fmi2_direct.c calls fmi2_checks.c. Compiled with
 * -fvisibility=hidden: nothing here is exported from the library. */
#ifndef RAILCOSIM_FMI2_INSTANCE_H
#define RAILCOSIM_FMI2_INSTANCE_H

#include <Python.h>
#include <stddef.h>
#include <stdint.h>

#include "fmi2Functions.h"

/* what fmi2Instantiate checks and the calls a host may make: the modelDescription's, copied by
 * `railcosim build` into resources/railcosim_description.txt (a host need not extract
 * modelDescription.xml: fmpy.simulate_fmu extracts binaries/ and resources/ only) */
typedef struct {
    char guid[128];
    int co_simulation, fmu_state, serialize, directional, interpolate_inputs, output_derivatives;
} Description;

/* ---- per instance: its name, the host's callbacks and its valid value references ---------- */
enum { REAL, INTEGER, BOOLEAN, STRING, TYPES, DIRECT_TYPES = STRING };  /* direct: the number types */

typedef struct { unsigned char *bits; size_t size; } Bitmap;  /* size in bits */
/* a host may repeat a reference in one list, so the bound is not the FMU's variable count: it
 * is far above any list of ours (the largest FMU has a few thousand values) */
#define MAX_VALUES_PER_CALL (1 << 20)
#define BULK_LISTS 32                  /* reference lists kept per instance; beyond: pythonfmu's route */

/* a list of value references of one number type, checked for a get or for a set, resolved by
 * the slave to where its values live in the slave's store (the store's elements: double,
 * int64_t, one byte 0/1), consecutive from `first` or at `slots` */
typedef struct {
    int type;
    int setting;                       /* checked as settable */
    size_t n;
    fmi2ValueReference *vr;
    char *store;
    Py_ssize_t first;
    const int64_t *slots;
} DirectList;

typedef struct Instance {
    struct Instance *next;
    fmi2Component component;
    char name[256];
    fmi2CallbackFunctions callbacks;   /* a copy: the host's struct need not outlive the call */
    int checked;                       /* 0: the table was not read, calls are forwarded as they are */
    Bitmap valid[TYPES];               /* every variable of the type */
    Bitmap settable[TYPES];            /* those fmi2Set<Type> may write */
    Description description;           /* the calls the FMU offers */
    /* the slave's store resolvers per number type (fmus/fmi/bulk.py), or NULL; the reference
     * lists they resolved */
    PyObject *resolvers[DIRECT_TYPES];
    DirectList lists[BULK_LISTS];
    int list_count;
    int direct;                        /* the resolvers are held */
    /* what pythonfmu holds of the slave (the slave, its class, its log queue), one reference
     * each of our own, or NULL (after fmi2Fatal they stand for pythonfmu's, see the top) */
    PyObject *held[3];
    int fatal;                         /* the instance returned fmi2Fatal */
    int leak;                          /* ... from fmi2Reset: pythonfmu's release would be one too many */
} Instance;

/* fmi2_checks.c: the FMI type names (Real, Integer, Boolean, String); an error line through the
 * instance's logger; fmi2Error, logged, for a get or set the checks refuse (its arrays, its size,
 * its value references), fmi2OK when all are good */
extern const char *const type_names[TYPES];
void log_error(const Instance *entry, const char *text);
fmi2Status check_references(const Instance *entry, const fmi2ValueReference vr[], size_t n, const void *value,
                            int type, int setting);

/* fmi2_direct.c */
void resolve_python_api(void);
void claim_instance(Instance *entry);
void release_held(Instance *entry);
void drop_bulk(Instance *entry);
int direct_values(Instance *entry, int type, int setting, const fmi2ValueReference vr[], size_t n,
                  void *value, fmi2Status *status);

#endif
