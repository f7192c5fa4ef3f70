/* test_mesh — the mesh structure and its verifiers.
 *
 * The verifiers are the oracle of every later test, so each check is shown
 * to fire on a planted fault with its own message number, and to stay quiet
 * on valid meshes: the wrong diagonal of a co-circular square, a flipped
 * non-Delaunay edge, an inverted triangle, broken and asymmetric adjacency,
 * a shared edge marked as hull, an edge in three triangles, a hole, a
 * reflex hull vertex, an unused vertex, duplicate and out-of-range points,
 * bad indices, a non-collinear set without triangles.  gdt_mesh_link must
 * rebuild the reference's adjacency exactly, and the canonical form must
 * not depend on slot rotation or triangle order.
 */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_reference.h"
#include "gen_degenerate.h"
#include "private/mesh_ops.h"

/* Expects check (0 = gdt_check_mesh, 1 = gdt_check_delaunay) to fail with
 * code and a message containing needle (may be NULL). */
static void expect_fault(tctx *t, const gdt_mesh *m, int which, int code, const char *needle,
                         const char *label)
{
    gdt_error err;
    gdt_error_clear(&err);
    gdt_status s = which == 0 ? gdt_check_mesh(NULL, m, &err) : gdt_check_delaunay(NULL, m, &err);
    CHECK(t,
          s == GDT_EINTERNAL && err.code == code &&
              (needle == NULL || strstr(err.msg, needle) != NULL),
          "%s: expected GDT-%04d%s%s, got status %d GDT-%04d %s", label, code,
          needle ? " with " : "", needle ? needle : "", (int)s, err.code, err.msg);
}

static int copy_mesh(gdt_mesh *dst, const gdt_mesh *src)
{
    gdt_error err;
    gdt_error_clear(&err);
    if (gdt_mesh_set_points(dst, src->pts, src->nverts, &err) != GDT_OK ||
        gdt_mesh_reserve(dst, src->nverts, src->ntris + 1, 0, &err) != GDT_OK)
        return -1;
    memcpy(dst->tri, src->tri, 3 * src->ntris * sizeof *src->tri);
    memcpy(dst->opp, src->opp, 3 * src->ntris * sizeof *src->opp);
    dst->ntris = src->ntris;
    return 0;
}

static int build(gdt_mesh *m, const gdt_ipt *pts, size_t n, const int32_t *tri, size_t nt)
{
    gdt_error err;
    gdt_error_clear(&err);
    if (gdt_mesh_set_points(m, pts, n, &err) != GDT_OK ||
        gdt_mesh_reserve(m, n, nt, 0, &err) != GDT_OK)
        return -1;
    memcpy(m->tri, tri, 3 * nt * sizeof *tri);
    m->ntris = nt;
    return gdt_mesh_link(m, &err) == GDT_OK ? 0 : -1;
}

static void small_cases(tctx *t)
{
    gdt_mesh m;
    gdt_error err;
    gdt_mesh_init(&m);

    /* Co-circular unit square: the (1,1) diagonal wins the tie-break. */
    const gdt_ipt sq[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    const int32_t good[6] = {0, 1, 2, 0, 2, 3}, wrong[6] = {0, 1, 3, 1, 2, 3};
    CHECK(t, build(&m, sq, 4, good, 2) == 0, "square build");
    gen_check_all(t, &m, "square, (1,1) diagonal");
    CHECK(t, build(&m, sq, 4, wrong, 2) == 0, "square build");
    gdt_error_clear(&err);
    CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "wrong square is still valid: %s", err.msg);
    expect_fault(t, &m, 1, 7330, "co-circular", "square, (1,-1) diagonal");

    /* L-shaped polygon: valid triangles, reflex hull vertex 3 = (1,1). */
    const gdt_ipt ell[6] = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
    const int32_t ltri[12] = {0, 1, 2, 0, 2, 3, 0, 3, 5, 3, 4, 5};
    CHECK(t, build(&m, ell, 6, ltri, 4) == 0, "L build");
    expect_fault(t, &m, 0, 7319, "reflex", "L-shaped polygon");

    /* An edge in three counter-clockwise triangles. */
    const gdt_ipt fin[5] = {{0, 0}, {10, 0}, {5, 5}, {3, 5 - 10}, {7, 5 - 8}};
    gdt_ipt fin_pos[5];
    for (int i = 0; i < 5; i++)
        fin_pos[i].x = fin[i].x + 100, fin_pos[i].y = fin[i].y + 100;
    const int32_t ftri[9] = {0, 1, 2, 1, 0, 3, 1, 0, 4};
    CHECK(t, build(&m, fin_pos, 5, ftri, 3) != 0, "edge in three triangles links");
    gdt_error_clear(&err);
    CHECK(t, gdt_mesh_link(&m, &err) == GDT_EINTERNAL && err.code == 7303,
          "link of a three-triangle edge: GDT-%04d %s", err.code, err.msg);
    for (int h = 0; h < 9; h++)
        m.opp[h] = GDT_MESH_NONE;
    m.opp[2] = gdt_opp_pack(1, 2), m.opp[5] = gdt_opp_pack(0, 2);
    expect_fault(t, &m, 0, 7316, "3 triangles", "edge in three triangles");

    /* Same edge, same direction twice. */
    const int32_t dtri[6] = {0, 1, 2, 0, 1, 3};
    CHECK(t, build(&m, fin_pos, 4, dtri, 2) != 0, "inconsistent orientation links");
    gdt_error_clear(&err);
    CHECK(t,
          gdt_mesh_link(&m, &err) == GDT_EINTERNAL && err.code == 7303 &&
              strstr(err.msg, "same direction"),
          "same direction: GDT-%04d %s", err.code, err.msg);

    /* Two separate triangles. */
    const gdt_ipt two[6] = {{0, 0}, {1, 0}, {0, 1}, {10, 10}, {11, 10}, {10, 11}};
    const int32_t ttri[6] = {0, 1, 2, 3, 4, 5};
    CHECK(t, build(&m, two, 6, ttri, 2) == 0, "two triangles build");
    expect_fault(t, &m, 0, 7322, "not connected", "two separate triangles");

    /* No triangles: fine for <3 points and for collinear points only. */
    const gdt_ipt line[4] = {{0, 0}, {3, 3}, {1, 1}, {7, 7}};
    for (size_t n = 0; n <= 4; n++) {
        CHECK(t, gdt_mesh_set_points(&m, line, n, &err) == GDT_OK, "set points");
        gdt_error_clear(&err);
        CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "%zu collinear points: %s", n, err.msg);
    }
    CHECK(t, gdt_mesh_set_points(&m, fin_pos, 3, &err) == GDT_OK, "set points");
    expect_fault(t, &m, 0, 7323, "not collinear", "triangle without triangles");

    gdt_error_clear(&err);
    CHECK(t,
          gdt_mesh_reserve(&m, GDT_MESH_MAX_VERTS + 1, 0, 0, &err) == GDT_EINTERNAL &&
              err.code == 7301,
          "over the vertex limit: GDT-%04d", err.code);
    gdt_mesh_free(&m);
}

/* An interior triangle: no hull edge, and none of its vertices on the hull. */
static int32_t interior_triangle(const gdt_mesh *m)
{
    uint8_t *hull = calloc(m->nverts, 1);
    int32_t found = GDT_MESH_NONE;
    if (hull == NULL)
        return found;
    for (size_t h = 0; h < 3 * m->ntris; h++)
        if (m->opp[h] == GDT_MESH_NONE) {
            int i = (int)(h % 3);
            hull[m->tri[3 * (h / 3) + (size_t)mesh_next(i)]] = 1;
            hull[m->tri[3 * (h / 3) + (size_t)mesh_prev(i)]] = 1;
        }
    for (size_t k = 0; k < m->ntris && found == GDT_MESH_NONE; k++) {
        const int32_t *T = m->tri + 3 * k;
        if (!hull[T[0]] && !hull[T[1]] && !hull[T[2]])
            found = (int32_t)k;
    }
    free(hull);
    return found;
}

/* Removes triangle k (its neighbours become hull there), moving the last
 * triangle into its place. */
static void remove_triangle(gdt_mesh *m, int32_t k)
{
    for (int i = 0; i < 3; i++) {
        int32_t o = m->opp[3 * (size_t)k + (size_t)i];
        if (o != GDT_MESH_NONE)
            *mesh_opp_ref(m->opp, o) = GDT_MESH_NONE;
    }
    int32_t last = (int32_t)m->ntris - 1;
    if (k != last) {
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * (size_t)last + (size_t)i];
            m->tri[3 * (size_t)k + (size_t)i] = m->tri[3 * (size_t)last + (size_t)i];
            m->opp[3 * (size_t)k + (size_t)i] = o;
            if (o != GDT_MESH_NONE)
                *mesh_opp_ref(m->opp, o) = gdt_opp_pack(k, i);
        }
    }
    m->ntris--;
}

static void planted_faults(tctx *t, gen_rng *r)
{
    gdt_mesh ref, m;
    gdt_error err;
    size_t n;
    gdt_ipt *p = gen_uniform(r, 300, 1000, 1000000, &n);
    char why[512];

    gdt_mesh_init(&ref);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    if (gdt_reference_triangulate(NULL, p, n, &ref, &err) != GDT_OK) {
        CHECK(t, 0, "reference: %s", err.msg);
        goto done;
    }
    gen_check_all(t, &ref, "random 300");

    /* gdt_mesh_link rebuilds exactly the same adjacency. */
    copy_mesh(&m, &ref);
    for (size_t h = 0; h < 3 * m.ntris; h++)
        m.opp[h] = 12345;
    CHECK(t, gdt_mesh_link(&m, &err) == GDT_OK, "link: %s", err.msg);
    CHECK(t, memcmp(m.opp, ref.opp, 3 * ref.ntris * sizeof *m.opp) == 0,
          "gdt_mesh_link differs from the reference adjacency");

    /* Canonical form ignores slot rotation and triangle order. */
    copy_mesh(&m, &ref);
    for (size_t k = 0; k < m.ntris; k++) {
        int rot = (int)gen_below(r, 3);
        int32_t *T = m.tri + 3 * k, v[3] = {T[0], T[1], T[2]};
        for (int i = 0; i < 3; i++)
            T[i] = v[(i + rot) % 3];
    }
    for (size_t k = m.ntris; k > 1; k--) {
        size_t j = (size_t)gen_below(r, k);
        for (int i = 0; i < 3; i++) {
            int32_t x = m.tri[3 * (k - 1) + (size_t)i];
            m.tri[3 * (k - 1) + (size_t)i] = m.tri[3 * j + (size_t)i];
            m.tri[3 * j + (size_t)i] = x;
        }
    }
    CHECK(t, gdt_mesh_link(&m, &err) == GDT_OK, "relink: %s", err.msg);
    gen_check_all(t, &m, "rotated and shuffled triangles");
    CHECK(t, gen_same_triangles(&ref, &m, why, sizeof why) == 0, "canonical: %s", why);

    /* A non-Delaunay edge: flip one interior edge of the answer. */
    copy_mesh(&m, &ref);
    for (size_t k = 0; k < m.ntris; k++) {
        int32_t o = m.opp[3 * k];
        if (o == GDT_MESH_NONE)
            continue;
        const int32_t *T = m.tri + 3 * k;
        gdt_ipt d = m.pts[m.tri[3 * (size_t)gdt_opp_tri(o) + (size_t)gdt_opp_slot(o)]];
        if (gdt_orient2d(NULL, m.pts[T[0]], m.pts[T[1]], d) > 0 &&
            gdt_orient2d(NULL, m.pts[T[0]], d, m.pts[T[2]]) > 0) {
            mesh_flip(m.tri, m.opp, (int32_t)k, 0);
            break;
        }
    }
    CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "flipped mesh invalid: %s", err.msg);
    expect_fault(t, &m, 1, 7330, "strictly inside", "flipped edge");

    copy_mesh(&m, &ref);
    {
        int32_t *T = m.tri + 3 * 7, x = T[1];
        T[1] = T[2], T[2] = x;
    }
    expect_fault(t, &m, 0, 7314, "triangle 7 ", "inverted triangle");

    copy_mesh(&m, &ref);
    m.tri[3 * 5 + 1] = (int32_t)n;
    expect_fault(t, &m, 0, 7313, "triangle 5 slot 1", "vertex index out of range");
    m.tri[3 * 5 + 1] = m.tri[3 * 5];
    expect_fault(t, &m, 0, 7313, "repeats", "repeated vertex");

    /* Adjacency faults on an interior edge (t, i) <-> (u, j). */
    size_t et = 0;
    int ei = 0;
    while (ref.opp[3 * et + (size_t)ei] == GDT_MESH_NONE)
        if (++ei == 3)
            ei = 0, et++;
    int32_t eo = ref.opp[3 * et + (size_t)ei];
    copy_mesh(&m, &ref);
    m.opp[3 * et + (size_t)ei] = gdt_opp_pack((int32_t)((et + 9) % m.ntris), 1);
    expect_fault(t, &m, 0, 7315, NULL, "pointer to the wrong triangle");
    copy_mesh(&m, &ref);
    m.opp[3 * et + (size_t)ei] = gdt_opp_pack((int32_t)m.ntris + 3, 0);
    expect_fault(t, &m, 0, 7315, "invalid opposite pointer", "pointer out of range");
    copy_mesh(&m, &ref);
    m.opp[3 * et + (size_t)ei] = GDT_MESH_NONE;
    expect_fault(t, &m, 0, 7315, "not symmetric", "one-sided hull marker");
    *mesh_opp_ref(m.opp, eo) = GDT_MESH_NONE;
    expect_fault(t, &m, 0, 7316, "marked as a hull edge", "shared edge marked as hull");

    /* A hole: the boundary becomes two closed chains. */
    copy_mesh(&m, &ref);
    int32_t k = interior_triangle(&m);
    CHECK(t, k != GDT_MESH_NONE, "no interior triangle in a 300-point mesh");
    if (k != GDT_MESH_NONE) {
        remove_triangle(&m, k);
        expect_fault(t, &m, 0, 7318, "more than one closed chain", "hole");
    }

    /* Removing a hull triangle whose apex is interior leaves a reflex vertex. */
    copy_mesh(&m, &ref);
    {
        int32_t victim = GDT_MESH_NONE;
        for (size_t q = 0; q < m.ntris && victim == GDT_MESH_NONE; q++) {
            int nh = 0, slot = 0;
            for (int i = 0; i < 3; i++)
                if (m.opp[3 * q + (size_t)i] == GDT_MESH_NONE)
                    nh++, slot = i;
            if (nh != 1)
                continue;
            /* the apex (slot) must not be a hull vertex */
            int32_t apex = m.tri[3 * q + (size_t)slot];
            int on_hull = 0;
            for (size_t h = 0; h < 3 * m.ntris; h++)
                if (m.opp[h] == GDT_MESH_NONE &&
                    m.tri[3 * (h / 3) + (size_t)mesh_next((int)(h % 3))] == apex)
                    on_hull = 1;
            if (!on_hull)
                victim = (int32_t)q;
        }
        CHECK(t, victim != GDT_MESH_NONE, "no hull triangle with an interior apex");
        if (victim != GDT_MESH_NONE) {
            remove_triangle(&m, victim);
            expect_fault(t, &m, 0, 7319, "reflex", "dent in the hull");
        }
    }

    /* Point faults. */
    copy_mesh(&m, &ref);
    m.pts[9] = m.pts[4];
    expect_fault(t, &m, 0, 7312, "vertices 4 and 9 coincide", "duplicate point");
    copy_mesh(&m, &ref);
    m.pts[2].y = GDT_COORD_MAX + 1;
    expect_fault(t, &m, 0, 7311, "vertex 2 ", "coordinate out of range");
    copy_mesh(&m, &ref);
    if (gdt_mesh_reserve(&m, n + 1, m.ntris, 0, &err) == GDT_OK) {
        m.pts[n] = (gdt_ipt){500000, 500001};
        m.nverts = n + 1;
        int dup = 0;
        for (size_t v = 0; v < n; v++)
            dup |= p[v].x == 500000 && p[v].y == 500001;
        if (!dup) {
            char needle[64];
            snprintf(needle, sizeof needle, "vertex %zu ", n);
            expect_fault(t, &m, 0, 7317, needle, "unused vertex");
        }
    }

done:
    free(p);
    gdt_mesh_free(&ref);
    gdt_mesh_free(&m);
}

int main(void)
{
    tctx t = {0, 0};
    gen_rng r;
    gen_seed(&r, 3);
    small_cases(&t);
    planted_faults(&t, &r);
    return gen_finish(&t, "test_mesh");
}
