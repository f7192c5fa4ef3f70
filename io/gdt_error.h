/* gdt_error.h — status codes, error records and diagnostics.
 *
 * Every library function of gdt-tile returns a gdt_status.  On failure it
 * fills a caller-owned gdt_error with the status class, a stable message
 * number and a message that names the file and the reason.  Libraries never
 * print errors and never call exit(); main() prints the error and maps the
 * status class to the process exit code (the enum values ARE the exit codes).
 *
 * Message numbers are stable and greppable: GDT-cnnn where c is the status
 * class (3 = bad input, 4 = I/O, ...), so tests and logs can match them.
 */
#ifndef GDT_ERROR_H
#define GDT_ERROR_H

#include <stdarg.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum gdt_status {
    GDT_OK = 0,
    GDT_EUSAGE = 2,       /* bad command line */
    GDT_EINPUT = 3,       /* bad input data (corrupt, lying header, unknown format) */
    GDT_EIO = 4,          /* read/write failure, disk full */
    GDT_EDEVICE = 5,      /* OpenCL device failure */
    GDT_EJOB = 6,         /* job directory does not match the command */
    GDT_EINTERNAL = 7,    /* internal error or failed validation */
    GDT_EINTERRUPTED = 130 /* SIGINT/SIGTERM; the job stays resumable */
} gdt_status;

#define GDT_ERROR_MSG_MAX 1024

typedef struct gdt_error {
    gdt_status status; /* GDT_OK when no error is recorded */
    int code;          /* stable message number, e.g. 3104 */
    char msg[GDT_ERROR_MSG_MAX];
} gdt_error;

/* Records an error (the first one wins: a recorded error is never
 * overwritten, so cleanup paths cannot hide the root cause) and returns st.
 * err may be NULL. */
gdt_status gdt_error_set(gdt_error *err, gdt_status st, int code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
gdt_status gdt_error_vset(gdt_error *err, gdt_status st, int code, const char *fmt, va_list ap)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 0)))
#endif
    ;
void gdt_error_clear(gdt_error *err);

/* Prints "gdt-tile: error GDT-<code>: <msg>" on one line. */
void gdt_error_print(const gdt_error *err, FILE *stream);

/* The message number c*1000 + n (n in 0..999) of the class of st: c is 2..7
 * for GDT_EUSAGE..GDT_EINTERNAL, 1 for GDT_EINTERRUPTED.  For the errors
 * that repeat an earlier one, whose class is the earlier one's. */
int gdt_error_code_in_class(gdt_status st, int n);

/* Short name of a status class ("bad input", "I/O", ...). */
const char *gdt_status_name(gdt_status st);

/* Diagnostics sink for warnings and verbose notes.  Threads may share
 * one: each message is written as one whole line and the count is atomic.  verbosity: -1 quiet (warnings still counted), 0 normal, 1 -v. */
typedef struct gdt_log {
    int verbosity;
    FILE *stream;        /* NULL means stderr */
    unsigned long warnings;
} gdt_log;

void gdt_log_init(gdt_log *log, int verbosity);
/* "gdt-tile: warning GDT-<code>: ..." unless quiet.  log may be NULL. */
void gdt_log_warn(gdt_log *log, int code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* Printed only with -v.  log may be NULL. */
void gdt_log_note(gdt_log *log, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

#ifdef __cplusplus
}
#endif
#endif
