/* The point filter in run outputs (private/filter_report.h). */
#include "private/filter_report.h"

#include <stdio.h>

#include "gdt_filter.h"

void gdt_filter_report_comment(const gdt_cloud *cloud, char *buf, size_t cap)
{
    char d[GDT_FILTER_COMMENT_MAX];
    gdt_filter_describe(gdt_cloud_filter(cloud), d, sizeof d);
    snprintf(buf, cap, "filter %s", d);
}

static void counts_json(gdt_json *j, const gdt_filter_counts *c)
{
    gdt_json_uint(j, "points_read", c->read);
    gdt_json_uint(j, "points_kept", c->kept);
    gdt_json_uint(j, "dropped_class", c->drop_class);
    gdt_json_uint(j, "dropped_return", c->drop_return);
    gdt_json_uint(j, "dropped_withheld", c->drop_withheld);
}

void gdt_filter_report_json(gdt_json *j, const gdt_cloud *cloud)
{
    const gdt_point_filter *f = gdt_cloud_filter(cloud);
    const gdt_cloud_info *ci = gdt_cloud_get_info(cloud);
    gdt_filter_counts total = gdt_cloud_total_counts(cloud);
    char d[GDT_FILTER_COMMENT_MAX];

    gdt_filter_describe(f, d, sizeof d);
    gdt_json_begin_object(j, "filter");
    gdt_json_string(j, "description", d);
    gdt_json_string(j, "class_mode", f->class_mode > 0 ? "keep" : f->class_mode < 0 ? "drop"
                                                                                   : "all");
    gdt_json_begin_array(j, "classes");
    for (unsigned c = 0; f->class_mode != 0 && c < 256; c++)
        if (f->classes[c])
            gdt_json_uint(j, NULL, c);
    gdt_json_end_array(j);
    gdt_json_string(j, "returns", gdt_returns_name(f->returns));
    gdt_json_bool(j, "keep_withheld", f->keep_withheld);
    counts_json(j, &total);
    gdt_json_begin_array(j, "inputs");
    for (size_t i = 0; i < ci->ninputs; i++) {
        gdt_json_begin_object(j, NULL);
        gdt_json_string(j, "path", gdt_cloud_input_path(cloud, i));
        counts_json(j, gdt_cloud_input_counts(cloud, i));
        gdt_json_end_object(j);
    }
    gdt_json_end_array(j);
    gdt_json_end_object(j);
}
