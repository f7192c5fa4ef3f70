/* The ground filter in the --json summary (private/ground_report.h). */
#include "private/ground_report.h"

void gdt_ground_report_json(gdt_json *j, const gdt_pmf_params *p, uint64_t ground,
                            uint64_t nonground, int classified, uint64_t tiles_reused,
                            double seconds)
{
    gdt_json_begin_object(j, "ground");
    gdt_json_string(j, "method", "pmf");
    gdt_json_double(j, "max_window", p->max_window);
    gdt_json_double(j, "slope", p->slope);
    gdt_json_double(j, "initial_distance", p->initial_distance);
    gdt_json_double(j, "max_distance", p->max_distance);
    gdt_json_double(j, "cell", p->cell);
    gdt_json_bool(j, "exponential", p->exponential != 0);
    gdt_json_uint(j, "ground_points", ground);
    gdt_json_uint(j, "nonground_points", nonground);
    gdt_json_bool(j, "classified", classified);
    gdt_json_uint(j, "tiles_reused", tiles_reused);
    gdt_json_double(j, "seconds", seconds);
    gdt_json_end_object(j);
}
