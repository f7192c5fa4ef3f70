/* progress.h — progress of a run on stderr.
 *
 * On a terminal: one bar per stage, redrawn in place at most ten times a
 * second, with the rate and the estimated time left.  Otherwise (logs,
 * pipes): a plain line when a stage starts, at most every two seconds while
 * it runs, and when it ends.  Nothing at verbosity < 0 (-q).
 * Writes only to stderr; no allocation. */
#ifndef GDT_PROGRESS_H
#define GDT_PROGRESS_H

#include <stdint.h>

typedef struct gdt_progress {
    int mode;            /* 0 silent, 1 plain lines, 2 terminal bar */
    char stage[32];
    const char *unit;    /* "points", "tiles" */
    uint64_t total, done;
    double t_stage, t_last;
    int open;            /* a stage is running */
} gdt_progress;

void gdt_progress_init(gdt_progress *p, int verbosity);
/* Starts a stage of total units (0: unknown). Ends the previous one. */
void gdt_progress_stage(gdt_progress *p, const char *stage, uint64_t total, const char *unit);
void gdt_progress_update(gdt_progress *p, uint64_t done);
/* Ends the current stage (prints its time). */
void gdt_progress_end(gdt_progress *p);
/* Ends the current stage without claiming it finished (after an error or a
 * stop): a terminal bar is closed with a newline, nothing else is printed. */
void gdt_progress_abort(gdt_progress *p);

#endif
