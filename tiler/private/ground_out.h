/* ground_out.h — --ground-out FILE.las (ground_out.c). */
#ifndef GDT_GROUND_OUT_H
#define GDT_GROUND_OUT_H

#include "gdt_las_copy.h"
#include "private/stages.h"

/* Before any work: every input can go into one LAS copy (LAS or LAZ, the
 * first input's point format, record length, scale and offset).
 * returns: GDT_OK (also without --ground-out); the sources' errors;
 * GDT_EUSAGE 2151. */
gdt_status tr_ground_out_check(const gdt_options *opts, gdt_error *err);

/* After the ground filter (J/ground.bits complete): writes opts->ground_out
 * from the inputs' records.  returns: GDT_OK; the sources' and the
 * writer's errors; GDT_EIO 4504; GDT_EINPUT 3501 (the inputs changed);
 * GDT_EINTERRUPTED 1303. */
gdt_status tr_ground_out_write(tr_run *c, gdt_error *err);

/* Another process of an MPI job: the records [first, end) of the inputs
 * taken as one sequence (ordinals from ord_base), classified, into the
 * temporary tmp that rank 0 holds open (records from points_at); *stats:
 * their statistics, *kept: the records the point filter kept.  returns:
 * as tr_ground_out_write. */
gdt_status tr_ground_out_part(tr_run *c, const char *tmp, uint64_t points_at, uint64_t first,
                              uint64_t end, uint64_t ord_base, gdt_las_copy_stats *stats,
                              uint64_t *kept, gdt_error *err);

#endif
