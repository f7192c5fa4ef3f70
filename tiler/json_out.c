#include "private/json_out.h"
#include "gdt_outfile.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

gdt_status gdt_json_open(gdt_json *j, const char *path, gdt_error *err)
{
    size_t len = strlen(path) + 32;

    memset(j, 0, sizeof *j);
    j->path = strdup(path);
    j->tmp = malloc(len);
    if (j->path == NULL || j->tmp == NULL) {
        free(j->path);
        free(j->tmp);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    snprintf(j->tmp, len, "%s.tmp-%ld", path, (long)getpid());
    j->f = fopen(j->tmp, "w");
    if (j->f == NULL) {
        int e = errno;
        free(j->path);
        free(j->tmp);
        return gdt_error_set(err, GDT_EIO, 4101, "%s: cannot create the JSON summary: %s", path,
                             strerror(e));
    }
    j->first[0] = 1;
    return GDT_OK;
}

static void put_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        switch (*p) {
        case '"': fputs("\\\"", f); break;
        case '\\': fputs("\\\\", f); break;
        case '\n': fputs("\\n", f); break;
        case '\r': fputs("\\r", f); break;
        case '\t': fputs("\\t", f); break;
        default:
            if (*p < 0x20)
                fprintf(f, "\\u%04x", *p);
            else
                fputc(*p, f);
        }
    }
    fputc('"', f);
}

/* Writes the separator and the key (if any) before a value. */
static void member(gdt_json *j, const char *key)
{
    if (!j->first[j->depth])
        fputc(',', j->f);
    j->first[j->depth] = 0;
    if (j->depth > 0) {
        fputc('\n', j->f);
        for (int i = 0; i < j->depth; i++)
            fputs("  ", j->f);
    }
    if (key != NULL) {
        put_string(j->f, key);
        fputs(": ", j->f);
    }
}

static void open_container(gdt_json *j, const char *key, char c)
{
    member(j, key);
    fputc(c, j->f);
    if (j->depth + 1 >= GDT_JSON_DEPTH) {
        j->misuse = 1;
        return;
    }
    j->depth++;
    j->first[j->depth] = 1;
}

static void close_container(gdt_json *j, char c)
{
    int empty;
    if (j->depth == 0) {
        j->misuse = 1;
        return;
    }
    empty = j->first[j->depth];
    j->depth--;
    if (!empty) {
        fputc('\n', j->f);
        for (int i = 0; i < j->depth; i++)
            fputs("  ", j->f);
    }
    fputc(c, j->f);
}

void gdt_json_begin_object(gdt_json *j, const char *key) { open_container(j, key, '{'); }
void gdt_json_end_object(gdt_json *j) { close_container(j, '}'); }
void gdt_json_begin_array(gdt_json *j, const char *key) { open_container(j, key, '['); }
void gdt_json_end_array(gdt_json *j) { close_container(j, ']'); }

void gdt_json_string(gdt_json *j, const char *key, const char *value)
{
    member(j, key);
    put_string(j->f, value != NULL ? value : "");
}

void gdt_json_int(gdt_json *j, const char *key, int64_t value)
{
    member(j, key);
    fprintf(j->f, "%" PRId64, value);
}

void gdt_json_uint(gdt_json *j, const char *key, uint64_t value)
{
    member(j, key);
    fprintf(j->f, "%" PRIu64, value);
}

void gdt_json_double(gdt_json *j, const char *key, double value)
{
    member(j, key);
    if (isfinite(value))
        fprintf(j->f, "%.17g", value);
    else
        fputs("null", j->f);
}

void gdt_json_bool(gdt_json *j, const char *key, int value)
{
    member(j, key);
    fputs(value ? "true" : "false", j->f);
}

gdt_status gdt_json_close(gdt_json *j, gdt_error *err)
{
    gdt_status st = GDT_OK;
    int e = 0;

    if (j->misuse || j->depth != 0)
        st = gdt_error_set(err, GDT_EINTERNAL, 7101, "%s: malformed JSON summary (writer misuse)",
                           j->path);
    fputc('\n', j->f);
    if (fflush(j->f) != 0 || fsync(fileno(j->f)) != 0)
        e = errno;
    if (fclose(j->f) != 0 && e == 0)
        e = errno;
    if (st == GDT_OK && e != 0)
        st = gdt_error_set(err, GDT_EIO, 4102, "%s: cannot write the JSON summary: %s", j->path,
                           strerror(e));
    if (st == GDT_OK)
        st = gdt_outfile_check(j->path, err);
    if (st == GDT_OK && rename(j->tmp, j->path) != 0)
        st = gdt_error_set(err, GDT_EIO, 4103, "%s: cannot rename the JSON summary into place: %s",
                           j->path, strerror(errno));
    if (st != GDT_OK)
        remove(j->tmp);
    free(j->tmp);
    free(j->path);
    memset(j, 0, sizeof *j);
    return st;
}
