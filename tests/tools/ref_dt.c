/* ref_dt — test tool: the CPU reference triangulator on a text point list.
 *
 *   ref_dt [--check] [--stats] FILE|-
 *
 * Input: one point per line, "x y" as decimal integers (tile-local lattice
 * coordinates); blank lines are ignored.  Output on stdout: "V F", then the
 * F triangles as vertex indices (input line order, from 0), each rotated
 * so that its smallest index comes first (counter-clockwise kept), sorted.
 * --check runs gdt_check_mesh and gdt_check_delaunay on the result;
 * --stats prints counters on stderr.
 * Exit status: 0, 2 usage, 3 unreadable input, 7 refused or failed check
 * (with the message on stderr).
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_reference.h"

static int read_points(FILE *f, gdt_ipt **out, size_t *n)
{
    size_t cap = 1024, m = 0;
    gdt_ipt *p = malloc(cap * sizeof *p);
    char line[256];
    long lineno = 0;

    if (p == NULL)
        return -1;
    while (fgets(line, sizeof line, f) != NULL) {
        long long x, y;
        char extra;
        lineno++;
        if (strspn(line, " \t\r\n") == strlen(line))
            continue;
        if (sscanf(line, "%lld %lld %c", &x, &y, &extra) != 2) {
            fprintf(stderr, "ref_dt: line %ld: expected \"x y\"\n", lineno);
            free(p);
            return -1;
        }
        if (m == cap) {
            gdt_ipt *q = realloc(p, 2 * cap * sizeof *p);
            if (q == NULL) {
                free(p);
                return -1;
            }
            p = q;
            cap *= 2;
        }
        p[m].x = x;
        p[m].y = y;
        m++;
    }
    *out = p;
    *n = m;
    return 0;
}

int main(int argc, char **argv)
{
    int check = 0, stats = 0;
    const char *path = NULL;
    gdt_ipt *pts = NULL;
    size_t n = 0;
    gdt_mesh m;
    gdt_error err;
    gdt_reference_stats rs;
    int64_t *canon = NULL;
    int rc = 0;

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--check") == 0)
            check = 1;
        else if (strcmp(argv[i], "--stats") == 0)
            stats = 1;
        else if (path == NULL)
            path = argv[i];
        else
            path = NULL, i = argc;
    }
    if (path == NULL) {
        fprintf(stderr, "usage: ref_dt [--check] [--stats] FILE|-\n");
        return GDT_EUSAGE;
    }
    FILE *f = strcmp(path, "-") == 0 ? stdin : fopen(path, "r");
    if (f == NULL || read_points(f, &pts, &n) != 0) {
        fprintf(stderr, "ref_dt: cannot read points from %s\n", path);
        if (f != NULL && f != stdin)
            fclose(f);
        return GDT_EINPUT;
    }
    if (f != stdin)
        fclose(f);

    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    memset(&rs, 0, sizeof rs);
    gdt_status s = gdt_reference_triangulate(&rs, pts, n, &m, &err);
    if (s == GDT_OK && check && (s = gdt_check_mesh(&rs.pred, &m, &err)) == GDT_OK)
        s = gdt_check_delaunay(&rs.pred, &m, &err);
    if (s != GDT_OK) {
        gdt_error_print(&err, stderr);
        rc = (int)s;
        goto done;
    }
    canon = malloc((3 * m.ntris > 0 ? 3 * m.ntris : 1) * sizeof *canon);
    if (canon == NULL) {
        fprintf(stderr, "ref_dt: out of memory\n");
        rc = GDT_EINTERNAL;
        goto done;
    }
    gdt_mesh_canonical(&m, canon);
    printf("%zu %zu\n", m.nverts, m.ntris);
    for (size_t t = 0; t < m.ntris; t++)
        printf("%" PRId64 " %" PRId64 " %" PRId64 "\n", canon[3 * t], canon[3 * t + 1],
               canon[3 * t + 2]);
    if (stats)
        fprintf(stderr,
                "orient %" PRIu64 " incircle %" PRIu64 " (exact %" PRIu64 ") tiebreak %" PRIu64
                " walk %" PRIu64 " insert_flips %" PRIu64 " final_flips %" PRIu64 "\n",
                rs.pred.orient_calls, rs.pred.incircle_calls, rs.pred.incircle_exact,
                rs.pred.tiebreak_calls, rs.walk_steps, rs.insert_flips, rs.final.flips);

done:
    free(canon);
    free(pts);
    gdt_mesh_free(&m);
    return rc;
}
