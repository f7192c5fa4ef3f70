/* ground_report.h — the ground filter (--ground) in the --json summary of
 * every mode that runs it. */
#ifndef GDT_GROUND_REPORT_H
#define GDT_GROUND_REPORT_H

#include <stdint.h>

#include "gdt_ground.h"
#include "private/json_out.h"

/* The member "ground" of the current JSON object: method, the parameters,
 * ground_points and nonground_points (of the distinct points), classified
 * (this run ran the filter, 0 when it took an earlier run's classes),
 * tiles_reused (tiles an earlier, stopped run classified) and seconds. */
void gdt_ground_report_json(gdt_json *j, const gdt_pmf_params *p, uint64_t ground,
                            uint64_t nonground, int classified, uint64_t tiles_reused,
                            double seconds);

#endif
