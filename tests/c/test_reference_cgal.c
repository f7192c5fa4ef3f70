/* test_reference_cgal — the reference triangulator against CGAL.
 *
 *   test_reference_cgal CGAL_DT WORKDIR
 *
 * Random points with 31-bit coordinates are in general position (no four
 * co-circular, no three collinear) with overwhelming probability, so their
 * Delaunay triangulation is unique and CGAL's Delaunay_triangulation_2
 * (exact predicates) must produce exactly the reference's triangles: the
 * test compares the canonical triangle lists, hence every edge.  Includes
 * sets hugging the range limits and clustered sets.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_reference.h"
#include "gen_degenerate.h"

static void compare(tctx *t, const char *cgal, const char *dir, const char *label,
                    const gdt_ipt *pts, size_t n)
{
    char path[4096], cmd[8400];
    gdt_mesh m;
    gdt_error err;
    int64_t *ref = NULL;
    FILE *f = NULL;

    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    snprintf(path, sizeof path, "%s/cgal_points_%ld.txt", dir, (long)getpid());
    f = fopen(path, "w");
    if (f == NULL) {
        CHECK(t, 0, "%s: cannot write %s", label, path);
        goto done;
    }
    for (size_t i = 0; i < n; i++)
        fprintf(f, "%" PRId64 " %" PRId64 "\n", pts[i].x, pts[i].y);
    if (fclose(f) != 0) {
        f = NULL;
        CHECK(t, 0, "%s: cannot write %s", label, path);
        goto done;
    }
    f = NULL;
    gdt_status s = gdt_reference_triangulate(NULL, pts, n, &m, &err);
    CHECK(t, s == GDT_OK, "%s: GDT-%04d %s", label, err.code, err.msg);
    if (s != GDT_OK)
        goto done;
    ref = gen_canonical(&m);
    snprintf(cmd, sizeof cmd, "'%s' '%s'", cgal, path);
    f = popen(cmd, "r");
    size_t v = 0, nf = 0;
    if (f == NULL || fscanf(f, "%zu %zu", &v, &nf) != 2) {
        CHECK(t, 0, "%s: no output from %s", label, cmd);
        goto done;
    }
    CHECK(t, v == n && nf == m.ntris, "%s: CGAL has %zu vertices / %zu faces, reference %zu / %zu",
          label, v, nf, n, m.ntris);
    size_t same = 0, k;
    for (k = 0; k < nf && k < m.ntris; k++) {
        int64_t a, b, c;
        if (fscanf(f, "%" SCNd64 " %" SCNd64 " %" SCNd64, &a, &b, &c) != 3)
            break;
        if (a != ref[3 * k] || b != ref[3 * k + 1] || c != ref[3 * k + 2]) {
            CHECK(t, 0,
                  "%s: triangle %zu: CGAL (%" PRId64 ", %" PRId64 ", %" PRId64
                  "), reference (%" PRId64 ", %" PRId64 ", %" PRId64 ")",
                  label, k, a, b, c, ref[3 * k], ref[3 * k + 1], ref[3 * k + 2]);
            break;
        }
        same++;
    }
    CHECK(t, same == m.ntris, "%s: %zu of %zu triangles agree", label, same, m.ntris);
    printf("%s: %zu points, %zu triangles identical to CGAL\n", label, n, same);

done:
    if (f != NULL)
        CHECK(t, pclose(f) == 0, "%s: %s failed", label, cgal);
    remove(path);
    free(ref);
    gdt_mesh_free(&m);
}

int main(int argc, char **argv)
{
    tctx t = {0, 0};
    gen_rng r;
    size_t n;
    gdt_ipt *p;

    if (argc != 3) {
        fprintf(stderr, "usage: test_reference_cgal CGAL_DT WORKDIR\n");
        return 2;
    }
    gen_seed(&r, 2718);
    static const size_t sizes[] = {3, 4, 10, 100, 5000, 60000};
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        char label[64];
        snprintf(label, sizeof label, "uniform %zu", sizes[k]);
        p = gen_uniform(&r, sizes[k], 0, GDT_COORD_MAX, &n);
        compare(&t, argv[1], argv[2], label, p, n);
        free(p);
    }
    /* Near the limits: only the low and high ends of the range. */
    p = gen_uniform(&r, 4000, 0, GDT_COORD_MAX, &n);
    for (size_t i = 0; i < n; i++) {
        p[i].x = (p[i].x & 1) ? GDT_COORD_MAX - (p[i].x >> 12) : (p[i].x >> 12);
        p[i].y = (p[i].y & 1) ? GDT_COORD_MAX - (p[i].y >> 12) : (p[i].y >> 12);
    }
    gen_dedup(p, &n);
    compare(&t, argv[1], argv[2], "four corners", p, n);
    free(p);
    p = gen_clusters(&r, 8, 2000, 1 << 24, &n);
    compare(&t, argv[1], argv[2], "clusters", p, n);
    free(p);
    return gen_finish(&t, "test_reference_cgal");
}
