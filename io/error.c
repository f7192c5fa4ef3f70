#include "gdt_error.h"

#include <string.h>

gdt_status gdt_error_vset(gdt_error *err, gdt_status st, int code, const char *fmt, va_list ap)
{
    if (err == NULL || err->status != GDT_OK)
        return st;
    err->status = st;
    err->code = code;
    vsnprintf(err->msg, sizeof err->msg, fmt, ap);
    return st;
}

gdt_status gdt_error_set(gdt_error *err, gdt_status st, int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    gdt_error_vset(err, st, code, fmt, ap);
    va_end(ap);
    return st;
}

void gdt_error_clear(gdt_error *err)
{
    if (err == NULL)
        return;
    err->status = GDT_OK;
    err->code = 0;
    err->msg[0] = '\0';
}

void gdt_error_print(const gdt_error *err, FILE *stream)
{
    if (err->status == GDT_OK)
        return;
    fprintf(stream, "gdt-tile: error GDT-%04d (%s): %s\n", err->code,
            gdt_status_name(err->status), err->msg);
}

int gdt_error_code_in_class(gdt_status st, int n)
{
    return (st == GDT_EINTERRUPTED ? 1 : (int)st) * 1000 + n % 1000;
}

const char *gdt_status_name(gdt_status st)
{
    switch (st) {
    case GDT_OK: return "ok";
    case GDT_EUSAGE: return "usage";
    case GDT_EINPUT: return "bad input";
    case GDT_EIO: return "I/O";
    case GDT_EDEVICE: return "OpenCL device";
    case GDT_EJOB: return "job mismatch";
    case GDT_EINTERNAL: return "internal";
    case GDT_EINTERRUPTED: return "interrupted";
    }
    return "unknown";
}

void gdt_log_init(gdt_log *log, int verbosity)
{
    memset(log, 0, sizeof *log);
    log->verbosity = verbosity;
}

void gdt_log_warn(gdt_log *log, int code, const char *fmt, ...)
{
    if (log != NULL)
        __atomic_fetch_add(&log->warnings, 1, __ATOMIC_RELAXED);
    if (log != NULL && log->verbosity < 0)
        return;
    FILE *out = (log != NULL && log->stream != NULL) ? log->stream : stderr;
    va_list ap;
    va_start(ap, fmt);
    flockfile(out); /* one whole line, whatever other threads write */
    fprintf(out, "gdt-tile: warning GDT-%04d: ", code);
    vfprintf(out, fmt, ap);
    fputc('\n', out);
    funlockfile(out);
    va_end(ap);
}

void gdt_log_note(gdt_log *log, const char *fmt, ...)
{
    if (log == NULL || log->verbosity < 1)
        return;
    FILE *out = log->stream != NULL ? log->stream : stderr;
    va_list ap;
    va_start(ap, fmt);
    flockfile(out);
    fputs("gdt-tile: ", out);
    vfprintf(out, fmt, ap);
    fputc('\n', out);
    funlockfile(out);
    va_end(ap);
}
