/* trim_report.h — the trimming (--max-edge, --concavity) in the outputs of a
 * run: the PLY header comment, the --json member and the summary text.
 * Every mode (tiled, --single-tile, --reference) reports the same way. */
#ifndef GDT_TRIM_REPORT_H
#define GDT_TRIM_REPORT_H

#include <stddef.h>

#include "gdt_trim.h"
#include "private/json_out.h"

/* Size of a buffer that holds any line of this header. */
#define GDT_TRIM_TEXT_MAX 160

/* "trim max-edge L concavity L" (the rules that are on, each L the shortest
 * decimal that reads back as the same double, '.' whatever the locale);
 * "" when no rule is on. */
void gdt_trim_report_comment(const gdt_trim_rule *r, char *buf, size_t cap);

/* With a rule on, the member "trim" of the current JSON object: max_edge,
 * concavity (0 = off), faces (before trimming), dropped_max_edge,
 * dropped_concavity, dropped (by either; a face both rules drop counts once
 * here and in both of the others).  Nothing when no rule is on. */
void gdt_trim_report_json(gdt_json *j, const gdt_trim_rule *r, const gdt_trim_counts *c);

/* ", N faces trimmed" for the summary line, "" when no rule is on. */
void gdt_trim_report_text(const gdt_trim_rule *r, const gdt_trim_counts *c, char *buf,
                          size_t cap);

#endif
