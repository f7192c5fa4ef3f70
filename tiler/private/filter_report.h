/* filter_report.h — what the point filter did, in the outputs of a run:
 * the PLY header comment, the --json member and the summary line text.
 * Every mode (tiled, --single-tile, --reference) reports the same way. */
#ifndef GDT_FILTER_REPORT_H
#define GDT_FILTER_REPORT_H

#include <stddef.h>

#include "gdt_cloud.h"
#include "private/json_out.h"

/* Size of a buffer that holds any gdt_filter_report_comment line. */
#define GDT_FILTER_COMMENT_MAX 1200

/* The PLY comment of the cloud's filter, "filter <description>" (see
 * gdt_filter_describe): deterministic, the same for every spelling of the
 * same options. */
void gdt_filter_report_comment(const gdt_cloud *cloud, char *buf, size_t cap);

/* Writes the member "filter" of the current JSON object: the filter
 * (description, class mode and list, returns, keep_withheld), the counts
 * of the last complete pass (points_read, points_kept, dropped_class,
 * dropped_return, dropped_withheld), and the same counts per input. */
void gdt_filter_report_json(gdt_json *j, const gdt_cloud *cloud);

#endif
