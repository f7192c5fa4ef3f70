/* A minimal streaming JSON writer for run summaries.
 *
 * Output is written to "<path>.tmp-<pid>" and renamed at gdt_json_close, so
 * a summary at the final path is always complete.  Keys are given for
 * members of objects and NULL for elements of arrays.  Nesting depth is
 * bounded by GDT_JSON_DEPTH; misuse is reported at close as GDT_EINTERNAL.
 * Doubles are written with %.17g (exact round trip); non-finite doubles as null.
 */
#ifndef GDT_JSON_OUT_H
#define GDT_JSON_OUT_H

#include <stdint.h>
#include <stdio.h>

#include "gdt_error.h"

#define GDT_JSON_DEPTH 16

typedef struct gdt_json {
    FILE *f;
    char *path;
    char *tmp;
    int depth;
    int first[GDT_JSON_DEPTH]; /* 1 while the container at this depth is empty */
    int misuse;
} gdt_json;

gdt_status gdt_json_open(gdt_json *j, const char *path, gdt_error *err);
void gdt_json_begin_object(gdt_json *j, const char *key);
void gdt_json_end_object(gdt_json *j);
void gdt_json_begin_array(gdt_json *j, const char *key);
void gdt_json_end_array(gdt_json *j);
void gdt_json_string(gdt_json *j, const char *key, const char *value);
void gdt_json_int(gdt_json *j, const char *key, int64_t value);
void gdt_json_uint(gdt_json *j, const char *key, uint64_t value);
void gdt_json_double(gdt_json *j, const char *key, double value);
void gdt_json_bool(gdt_json *j, const char *key, int value);
/* Flushes, fsyncs and renames; frees everything (also on failure). */
gdt_status gdt_json_close(gdt_json *j, gdt_error *err);

#endif
