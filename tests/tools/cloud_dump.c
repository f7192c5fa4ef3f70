/* cloud_dump — test tool: streams several inputs through gdt_cloud.
 *
 *   cloud_dump [--quantum Q] [--buffer-bytes N] [--chunk N]
 *              [--dup first|min-z|max-z] [--dupcount BUDGET TMPDIR] [-q] FILE...
 *
 * Output: header lines starting with '#':
 *   # lattice <sx> <sy> <ox> <oy>          (%.17g)
 *   # native <0|1> <lattice input>
 *   # projected <0|1> <zone> <north>
 *   # epsg <code>
 *   # crs <description>
 *   # points <header count>
 *   # map <input> <native|shift|snap|project> <mx> <kx> <my> <ky>
 * then one line per point "ix iy z ord" (z as %.17g), in stream order, or
 * after the duplicate merge when --dup is given.  With --dupcount the points
 * are not printed; instead "# dupcount <points> <distinct> <duplicates>
 * <max multiplicity> <levels>".  The stream is read twice (rewind) and the
 * two passes are compared; a difference exits with 7.
 * Exit status: the gdt_status of the first failure (3 bad input, ...).
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_dupcount.h"

static const char *map_name(gdt_cloud_map k)
{
    switch (k) {
    case GDT_CLOUD_MAP_NATIVE: return "native";
    case GDT_CLOUD_MAP_SHIFT: return "shift";
    case GDT_CLOUD_MAP_SNAP: return "snap";
    case GDT_CLOUD_MAP_PROJECT: return "project";
    }
    return "?";
}

static int usage(void)
{
    fprintf(stderr, "usage: cloud_dump [--quantum Q] [--buffer-bytes N] [--chunk N] "
                    "[--dup first|min-z|max-z] [--dupcount BUDGET TMPDIR] [-q] FILE...\n");
    return GDT_EUSAGE;
}

/* Reads the whole stream into *all (grown as needed). */
static gdt_status read_all(gdt_cloud *c, size_t chunk, gdt_point **all, size_t *nall,
                           gdt_dupcount *dc, gdt_error *err)
{
    gdt_point *buf = malloc(chunk * sizeof *buf);
    size_t cap = 0, n = 0, got = 0;
    gdt_status st = GDT_OK;

    *all = NULL;
    *nall = 0;
    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (;;) {
        st = gdt_cloud_read(c, buf, chunk, &got, err);
        if (st != GDT_OK || got == 0)
            break;
        if (dc != NULL) {
            st = gdt_dupcount_add(dc, buf, got, err);
            if (st != GDT_OK)
                break;
            continue;
        }
        if (n + got > cap) {
            size_t ncap = cap == 0 ? 4096 : cap;
            while (ncap < n + got)
                ncap *= 2;
            gdt_point *g = realloc(*all, ncap * sizeof *g);
            if (g == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                break;
            }
            *all = g;
            cap = ncap;
        }
        memcpy(*all + n, buf, got * sizeof *buf);
        n += got;
    }
    free(buf);
    *nall = n;
    return st;
}

int main(int argc, char **argv)
{
    gdt_cloud_opts opts;
    gdt_log log;
    gdt_error err;
    gdt_cloud *c = NULL;
    gdt_point *a = NULL, *b = NULL;
    size_t na = 0, nb = 0, chunk = 1000;
    const char **paths = NULL;
    size_t npaths = 0;
    int dedup = 0, dupcount = 0;
    gdt_dup_policy policy = GDT_DUP_FIRST;
    gdt_dupcount_opts dopts;
    gdt_status st;

    memset(&opts, 0, sizeof opts);
    memset(&dopts, 0, sizeof dopts);
    gdt_log_init(&log, 0);
    gdt_error_clear(&err);
    opts.log = &log;
    paths = calloc((size_t)argc, sizeof *paths);
    if (paths == NULL)
        return GDT_EINTERNAL;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--quantum") == 0 && i + 1 < argc) {
            opts.quantum = strtod(argv[++i], NULL);
        } else if (strcmp(argv[i], "--buffer-bytes") == 0 && i + 1 < argc) {
            opts.buffer_bytes = (size_t)strtoull(argv[++i], NULL, 10);
        } else if (strcmp(argv[i], "--chunk") == 0 && i + 1 < argc) {
            chunk = (size_t)strtoull(argv[++i], NULL, 10);
            if (chunk == 0)
                return usage();
        } else if (strcmp(argv[i], "--dup") == 0 && i + 1 < argc) {
            if (gdt_dup_policy_parse(argv[++i], &policy) != 0)
                return usage();
            dedup = 1;
        } else if (strcmp(argv[i], "--dupcount") == 0 && i + 2 < argc) {
            dopts.mem_budget = (size_t)strtoull(argv[++i], NULL, 10);
            dopts.temp_dir = argv[++i];
            dupcount = 1;
        } else if (strcmp(argv[i], "-q") == 0) {
            log.verbosity = -1;
        } else if (argv[i][0] != '-') {
            paths[npaths++] = argv[i];
        } else {
            return usage();
        }
    }
    if (npaths == 0)
        return usage();
    st = gdt_cloud_open(&c, paths, npaths, &opts, &err);
    if (st != GDT_OK)
        goto fail;
    {
        const gdt_cloud_info *in = gdt_cloud_get_info(c);
        printf("# lattice %.17g %.17g %.17g %.17g\n", in->lattice.sx, in->lattice.sy,
               in->lattice.ox, in->lattice.oy);
        printf("# native %d %zu\n", in->lattice_native, in->lattice_input);
        printf("# projected %d %d %d\n", in->projected, in->utm_zone, in->utm_north);
        printf("# epsg %d\n# crs %s\n# points %" PRIu64 "\n", in->epsg, in->crs_desc,
               in->point_count);
        for (size_t i = 0; i < in->ninputs; i++) {
            const gdt_cloud_input_map *m = gdt_cloud_input_map_of(c, i);
            printf("# map %zu %s %" PRId64 " %" PRId64 " %" PRId64 " %" PRId64 "\n", i,
                   map_name(m->kind), m->mx, m->kx, m->my, m->ky);
        }
    }
    if (dupcount) {
        gdt_dupcount *dc = NULL;
        gdt_dupcount_result r;
        st = gdt_dupcount_create(&dc, &dopts, &err);
        if (st == GDT_OK)
            st = read_all(c, chunk, &a, &na, dc, &err);
        if (st == GDT_OK)
            st = gdt_dupcount_finish(dc, &r, &err);
        gdt_dupcount_destroy(dc);
        if (st != GDT_OK)
            goto fail;
        printf("# dupcount %" PRIu64 " %" PRIu64 " %" PRIu64 " %" PRIu64 " %u\n", r.points,
               r.distinct, r.duplicates, r.max_multiplicity, r.levels);
        goto done;
    }
    st = read_all(c, chunk, &a, &na, NULL, &err);
    if (st != GDT_OK)
        goto fail;
    st = gdt_cloud_rewind(c, &err);
    if (st == GDT_OK)
        st = read_all(c, chunk > 7 ? chunk - 7 : chunk, &b, &nb, NULL, &err);
    if (st != GDT_OK)
        goto fail;
    if (na != nb || (na > 0 && memcmp(a, b, na * sizeof *a) != 0)) {
        st = gdt_error_set(&err, GDT_EINTERNAL, 7999, "the second pass differs from the first");
        goto fail;
    }
    if (dedup) {
        size_t kept = 0;
        st = gdt_points_dedup(a, na, policy, &kept, &err);
        if (st != GDT_OK)
            goto fail;
        na = kept;
    }
    for (size_t i = 0; i < na; i++)
        printf("%" PRId64 " %" PRId64 " %.17g %" PRIu64 "\n", a[i].x, a[i].y, a[i].z, a[i].ord);
done:
    free(a);
    free(b);
    free(paths);
    gdt_cloud_close(c);
    return fflush(stdout) == 0 ? 0 : GDT_EIO;
fail:
    gdt_error_print(&err, stderr);
    free(a);
    free(b);
    free(paths);
    gdt_cloud_close(c);
    return (int)st;
}
