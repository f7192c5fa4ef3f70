/* trim_report.c — see private/trim_report.h. */
#include "private/trim_report.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>

/* The shortest %g of d that strtod reads back as d, with '.' as decimal
 * point whatever LC_NUMERIC says. */
static void shortest(char *out, size_t cap, double d)
{
    char tmp[64];
    size_t j = 0;
    for (int p = 1; p <= 17; p++) {
        snprintf(tmp, sizeof tmp, "%.*g", p, d);
        if (strtod(tmp, NULL) == d)
            break;
    }
    for (size_t i = 0; tmp[i] != '\0' && j + 1 < cap; i++) {
        char c = tmp[i];
        out[j++] = (c >= '0' && c <= '9') || c == '-' || c == '+' || c == 'e' ? c : '.';
    }
    out[j] = '\0';
}

void gdt_trim_report_comment(const gdt_trim_rule *r, char *buf, size_t cap)
{
    char a[40], b[40];
    buf[0] = '\0';
    if (!gdt_trim_on(r))
        return;
    shortest(a, sizeof a, r->max_edge);
    shortest(b, sizeof b, r->concavity);
    if (r->max_edge > 0 && r->concavity > 0)
        snprintf(buf, cap, "trim max-edge %s concavity %s", a, b);
    else if (r->max_edge > 0)
        snprintf(buf, cap, "trim max-edge %s", a);
    else
        snprintf(buf, cap, "trim concavity %s", b);
}

void gdt_trim_report_json(gdt_json *j, const gdt_trim_rule *r, const gdt_trim_counts *c)
{
    if (!gdt_trim_on(r))
        return;
    gdt_json_begin_object(j, "trim");
    gdt_json_double(j, "max_edge", r->max_edge);
    gdt_json_double(j, "concavity", r->concavity);
    gdt_json_uint(j, "faces", c->faces);
    gdt_json_uint(j, "dropped_max_edge", c->cut);
    gdt_json_uint(j, "dropped_concavity", c->peeled);
    gdt_json_uint(j, "dropped", c->dropped);
    gdt_json_end_object(j);
}

void gdt_trim_report_text(const gdt_trim_rule *r, const gdt_trim_counts *c, char *buf,
                          size_t cap)
{
    buf[0] = '\0';
    if (gdt_trim_on(r))
        snprintf(buf, cap, " (%" PRIu64 " trimmed)", c->dropped);
}
