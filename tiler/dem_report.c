/* dem_report.c — see private/dem_report.h. */
#include "private/dem_report.h"

#include <inttypes.h>
#include <stdio.h>

void gdt_dem_report_json(gdt_json *j, const gdt_options *opts, const gdt_dem_geo *geo,
                         const gdt_dem_stats *st, double seconds)
{
    gdt_json_begin_object(j, "dem");
    gdt_json_string(j, "path", opts->dem);
    if (opts->preview != NULL)
        gdt_json_string(j, "preview", opts->preview);
    gdt_json_double(j, "res", geo->res_x);
    gdt_json_uint(j, "cols", (uint64_t)geo->ncols);
    gdt_json_uint(j, "rows", (uint64_t)geo->nrows);
    gdt_json_double(j, "west", geo->west);
    gdt_json_double(j, "north", geo->north);
    gdt_json_uint(j, "cells_with_value", st->cells_written);
    gdt_json_uint(j, "blocks", st->blocks);
    gdt_json_uint(j, "cache_blocks", st->cache_blocks);
    gdt_json_uint(j, "spills", st->spills);
    gdt_json_double(j, "seconds", seconds);
    gdt_json_end_object(j);
}

void gdt_dem_report_line(const gdt_options *opts, const gdt_dem_geo *geo,
                         const gdt_dem_stats *st)
{
    if (opts->verbosity < 0)
        return;
    fprintf(stderr,
            "gdt-tile: %s: DEM of %" PRId64 " x %" PRId64 " cells of %.17g, %" PRIu64
            " with a value%s%s\n",
            opts->dem, geo->ncols, geo->nrows, geo->res_x, st->cells_written,
            opts->preview != NULL ? "; preview " : "", opts->preview != NULL ? opts->preview : "");
}
