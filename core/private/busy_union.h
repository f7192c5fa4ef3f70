/* busy_union.h — the time a device with several command queues was busy:
 * the length of the union of its commands' execution intervals, kept in
 * bounded memory while the queues run (used by ocl.c; no OpenCL here).
 *
 * The queues report intervals in the device's clock, each queue in its own
 * order, the queues interleaved in any order.  What makes folding safe:
 *   - a queue's commands run in order and never overlap, so once a queue
 *     has reported the commands up to one ending at last_end, its next one
 *     starts at or after last_end;
 *   - a queue with no command outstanding (not pending) starts its next one
 *     after "now", later than the end of every interval reported so far.
 * So an interval that ends at or before the least last_end of the pending
 * queues overlaps no interval still to come: gdt_busy_fold adds such
 * intervals' union to a running total and forgets them. */
#ifndef GDT_BUSY_UNION_H
#define GDT_BUSY_UNION_H

#include <stddef.h>
#include <stdint.h>

/* One queue's state.  pending: it has commands not yet reported;
 * last_end: the end of the last interval it reported (0 before any). */
typedef struct gdt_busy_queue {
    int pending;
    uint64_t last_end;
} gdt_busy_queue;

/* Invariants: iv[0..n) are reported intervals not yet folded, t0 < t1;
 * folded_s is the length of the union of every folded interval, in
 * seconds (clock units of 1 ns), all of which end at or before
 * folded_end. */
typedef struct gdt_busy_union {
    uint64_t (*iv)[2];
    size_t n, cap;
    double folded_s;
    uint64_t folded_end;
} gdt_busy_union;

void gdt_busy_init(gdt_busy_union *u);
void gdt_busy_free(gdt_busy_union *u);

/* Queue q reports its command [t0, t1) (ns, t0 < t1; ignored otherwise),
 * after every earlier one of q's.  Without memory to keep it the interval
 * is added to the total alone (an overlap with another queue's is then
 * counted twice). */
void gdt_busy_add(gdt_busy_union *u, gdt_busy_queue *q, uint64_t t0, uint64_t t1);

/* Folds what can no longer overlap an interval still to come, given the
 * device's nq queues (all: every queue is idle and reported: everything
 * folds).  The kept intervals are merged (disjoint, sorted). */
void gdt_busy_fold(gdt_busy_union *u, const gdt_busy_queue *const *qs, size_t nq, int all);

/* The busy seconds of everything reported: folds all (call it when every
 * queue is idle and reported). */
double gdt_busy_seconds(gdt_busy_union *u);

#endif
