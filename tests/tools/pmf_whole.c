/* pmf_whole — test tool: the ground filter of gdt_ground.h over a whole
 * cloud in one call, the oracle of the tiled run's --ground pmf.
 *
 *   pmf_whole [--dup first|min-z|max-z] [--pmf-max-window W] [--pmf-slope S]
 *             [--pmf-initial-distance D] [--pmf-max-distance D] [--pmf-cell C]
 *             [--pmf-exponential true|false] [--z0 V] FILE...
 *
 * Reads every point (default filter), takes z0 = the lowest z read (as
 * pass 1 does; --z0 V sets it), merges duplicates by --dup (default first), classifies all
 * the distinct points with one call to PCL's filter and prints
 *   # lattice <sx> <sy> <ox> <oy>
 *   # ground <n> other <m>
 * then one line "ix iy z class" per distinct point (class 2 ground, 1
 * other; z as %.17g), sorted by (ix, iy).
 * Exit status: the gdt_status of the first failure.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_ground.h"

static int usage(void)
{
    fprintf(stderr, "usage: pmf_whole [--dup POLICY] [--pmf-* V] FILE...\n");
    return GDT_EUSAGE;
}

static int by_xy(const void *a, const void *b)
{
    const gdt_point *p = a, *q = b;
    if (p->x != q->x)
        return p->x < q->x ? -1 : 1;
    return p->y < q->y ? -1 : p->y > q->y;
}

int main(int argc, char **argv)
{
    gdt_cloud_opts opts;
    gdt_cloud *c = NULL;
    gdt_error err;
    gdt_log log;
    gdt_pmf_params pp;
    gdt_pmf f;
    gdt_dup_policy policy = GDT_DUP_FIRST;
    const char **paths = calloc((size_t)argc + 1, sizeof *paths);
    size_t npaths = 0, n = 0, cap = 0, got = 0, kept = 0;
    gdt_point *all = NULL, buf[4096];
    uint8_t *ground = NULL;
    double z0 = 0.0, z0_given = 0.0;
    int has_z0 = 0;
    uint64_t ng = 0;
    gdt_status st;

    if (paths == NULL)
        return GDT_EINTERNAL;
    memset(&opts, 0, sizeof opts);
    gdt_log_init(&log, -1);
    gdt_error_clear(&err);
    opts.log = &log;
    gdt_pmf_defaults(&pp);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (i + 1 < argc && strcmp(a, "--dup") == 0) {
            if (gdt_dup_policy_parse(argv[++i], &policy) != 0)
                return usage();
        } else if (i + 1 < argc && strcmp(a, "--z0") == 0) {
            z0_given = strtod(argv[++i], NULL);
            has_z0 = 1;
        } else if (i + 1 < argc && strcmp(a, "--pmf-max-window") == 0) {
            pp.max_window = strtod(argv[++i], NULL);
        } else if (i + 1 < argc && strcmp(a, "--pmf-slope") == 0) {
            pp.slope = strtod(argv[++i], NULL);
        } else if (i + 1 < argc && strcmp(a, "--pmf-initial-distance") == 0) {
            pp.initial_distance = strtod(argv[++i], NULL);
        } else if (i + 1 < argc && strcmp(a, "--pmf-max-distance") == 0) {
            pp.max_distance = strtod(argv[++i], NULL);
        } else if (i + 1 < argc && strcmp(a, "--pmf-cell") == 0) {
            pp.cell = strtod(argv[++i], NULL);
        } else if (i + 1 < argc && strcmp(a, "--pmf-exponential") == 0) {
            pp.exponential = strcmp(argv[++i], "true") == 0;
        } else if (a[0] != '-') {
            paths[npaths++] = a;
        } else {
            return usage();
        }
    }
    if (npaths == 0)
        return usage();
    st = gdt_cloud_open(&c, paths, npaths, &opts, &err);
    while (st == GDT_OK) {
        st = gdt_cloud_read(c, buf, sizeof buf / sizeof buf[0], &got, &err);
        if (st != GDT_OK || got == 0)
            break;
        if (n + got > cap) {
            size_t nc = cap ? 2 * cap : 1 << 16;
            gdt_point *g;
            while (nc < n + got)
                nc *= 2;
            g = realloc(all, nc * sizeof *g);
            if (g == NULL) {
                st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
                break;
            }
            all = g;
            cap = nc;
        }
        for (size_t i = 0; i < got; i++)
            if (n + i == 0 || buf[i].z < z0)
                z0 = buf[i].z;
        memcpy(all + n, buf, got * sizeof *buf);
        n += got;
    }
    if (has_z0)
        z0 = z0_given;
    if (st == GDT_OK)
        st = gdt_points_dedup(all, n, policy, &kept, &err);
    if (st == GDT_OK)
        st = gdt_pmf_init(&f, &pp, &gdt_cloud_get_info(c)->lattice, z0, &err);
    if (st == GDT_OK && (ground = malloc(kept > 0 ? kept : 1)) == NULL)
        st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK) {
        gdt_pmf_box box = {INT64_MAX, INT64_MIN, INT64_MAX, INT64_MIN};
        for (size_t i = 0; i < kept; i++) {
            box.x0 = all[i].x < box.x0 ? all[i].x : box.x0;
            box.x1 = all[i].x > box.x1 ? all[i].x : box.x1;
            box.y0 = all[i].y < box.y0 ? all[i].y : box.y0;
            box.y1 = all[i].y > box.y1 ? all[i].y : box.y1;
        }
        st = gdt_pmf_classify(&f, all, kept, NULL, 0, &box, &box, ground, 0, &err);
    }
    if (st == GDT_OK) {
        const gdt_lattice *l = &gdt_cloud_get_info(c)->lattice;
        gdt_point *s = malloc((kept > 0 ? kept : 1) * sizeof *s);
        if (s == NULL) {
            st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
        } else {
            /* sort by (x, y), carrying the class in ord */
            for (size_t i = 0; i < kept; i++) {
                s[i] = all[i];
                s[i].ord = ground[i];
                ng += ground[i];
            }
            qsort(s, kept, sizeof *s, by_xy);
            printf("# lattice %.17g %.17g %.17g %.17g\n", l->sx, l->sy, l->ox, l->oy);
            printf("# ground %" PRIu64 " other %" PRIu64 "\n", ng, (uint64_t)kept - ng);
            for (size_t i = 0; i < kept; i++)
                printf("%" PRId64 " %" PRId64 " %.17g %d\n", s[i].x, s[i].y, s[i].z,
                       s[i].ord ? 2 : 1);
        }
        free(s);
    }
    if (st != GDT_OK)
        gdt_error_print(&err, stderr);
    free(ground);
    free(all);
    free(paths);
    gdt_cloud_close(c);
    return st;
}
