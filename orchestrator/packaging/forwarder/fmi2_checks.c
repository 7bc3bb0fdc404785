/* railcosim's FMI 2.0 binary, its third part: a get or set checked against the instance's
 * value references before pythonfmu or the direct route sees it (fmi2_forward.c reads the table
 * at fmi2Instantiate, see its top comment, "Value references"), and the error line it and the
 * forwarder log through the host's logger. */
#include "fmi2_instance.h"

#include <stdio.h>

const char *const type_names[TYPES] = {"Real", "Integer", "Boolean", "String"};
static const char *const articles[TYPES] = {"a", "an", "a", "a"};

static int bitmap_has(const Bitmap *map, fmi2ValueReference vr) {
    return vr < map->size && (map->bits[vr / 8] >> (vr % 8)) & 1;
}

void log_error(const Instance *entry, const char *text) {
    if (!entry->callbacks.logger) return;
    char escaped[1024];  /* the logger takes a printf format */
    size_t k = 0;
    for (const char *p = text; *p && k + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[k++] = '%';
        escaped[k++] = *p;
    }
    escaped[k] = '\0';
    entry->callbacks.logger(entry->callbacks.componentEnvironment, entry->name, fmi2Error, "logStatusError", escaped);
}

/* fmi2Error, logged, for a get or set whose arrays are missing, that asks for more than
 * MAX_VALUES_PER_CALL values (n = SIZE_MAX: never read, never allocated), or at the first
 * value reference that is not a variable of `type` (or, setting, one that cannot be set); fmi2OK
 * when all are good. Without the table only the arrays are checked. */
fmi2Status check_references(const Instance *entry, const fmi2ValueReference vr[], size_t n, const void *value,
                            int type, int setting) {
    if (n == 0) return fmi2OK;
    char text[600];
    const char *call = setting ? "Set" : "Get";
    if (!vr || !value) {
        snprintf(text, sizeof text, "%s: fmi2%s%s with %zu values and no %s array", entry->name, call, type_names[type], n,
                 vr ? "value" : "value reference");
        log_error(entry, text);
        return fmi2Error;
    }
    if (n > MAX_VALUES_PER_CALL) {
        snprintf(text, sizeof text, "%s: fmi2%s%s of %zu values refused: more than %d values in one call",
                 entry->name, call, type_names[type], n, MAX_VALUES_PER_CALL);
        log_error(entry, text);
        return fmi2Error;
    }
    if (!entry->checked) return fmi2OK;
    const Bitmap *allowed = setting ? &entry->settable[type] : &entry->valid[type];
    for (size_t i = 0; i < n; i++) {
        if (bitmap_has(allowed, vr[i])) continue;
        if (setting && bitmap_has(&entry->valid[type], vr[i]))
            snprintf(text, sizeof text, "%s: value reference %u is %s %s variable that cannot be set (not an input or parameter)",
                     entry->name, (unsigned)vr[i], articles[type], type_names[type]);
        else
            snprintf(text, sizeof text, "%s: value reference %u is not %s %s variable",
                     entry->name, (unsigned)vr[i], articles[type], type_names[type]);
        log_error(entry, text);
        return fmi2Error;
    }
    if (type == STRING && setting) {  /* pythonfmu would read through a NULL string */
        const fmi2String *strings = value;
        for (size_t i = 0; i < n; i++) {
            if (strings[i]) continue;
            snprintf(text, sizeof text, "%s: fmi2SetString: the value for reference %u is NULL", entry->name, (unsigned)vr[i]);
            log_error(entry, text);
            return fmi2Error;
        }
    }
    return fmi2OK;
}
