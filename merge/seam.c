/* Seam extraction of one tile (see gdt_seam.h). */
#include "gdt_seam.h"

#include <stdlib.h>
#include <string.h>

#include "gdt_predicates.h"
#include "gdt_grow.h"

void gdt_seam_free(gdt_seam *s)
{
    if (s == NULL)
        return;
    free(s->v);
    free(s->e);
    memset(s, 0, sizeof *s);
}

static int grow(void *pp, size_t *cap, size_t need, size_t elem)
{
    return gdt_grow(pp, cap, need, elem, 1024);
}

static int cmp_edge(const void *pa, const void *pb)
{
    const gdt_seam_edge *a = pa, *b = pb;
    if (a->a != b->a)
        return a->a < b->a ? -1 : 1;
    return (a->b > b->b) - (a->b < b->b);
}

gdt_status gdt_seam_extract(gdt_seam *s, const gdt_mesh *m, const uint8_t *cert,
                            const double *z, uint64_t id_base, int64_t dx, int64_t dy,
                            gdt_error *err)
{
    uint8_t *in_u = calloc(m->nverts > 0 ? m->nverts : 1, 1);
    size_t e0 = s->ne;
    gdt_status st = GDT_OK;

    if (in_u == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (m->ntris == 0)
        memset(in_u, 1, m->nverts);
    for (size_t t = 0; t < m->ntris; t++) {
        const int32_t *v = &m->tri[3 * t];
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * t + i];
            int nb_cert = o != GDT_MESH_NONE && cert[gdt_opp_tri(o)];
            if (!cert[t]) {
                in_u[v[i]] = 1;
                continue;
            }
            if (o == GDT_MESH_NONE) {
                in_u[v[(i + 1) % 3]] = 1;
                in_u[v[(i + 2) % 3]] = 1;
            }
            if (!nb_cert) {
                if (grow(&s->e, &s->cap_e, s->ne + 1, sizeof *s->e) != 0) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                    goto fail;
                }
                s->e[s->ne].a = id_base + (uint64_t)v[(i + 1) % 3];
                s->e[s->ne].b = id_base + (uint64_t)v[(i + 2) % 3];
                s->ne++;
            }
        }
        /* hull edges of uncertified triangles: their vertices are already in */
    }
    for (size_t i = 0; i < m->nverts; i++) {
        int64_t x, y;
        if (!in_u[i])
            continue;
        x = m->pts[i].x + dx;
        y = m->pts[i].y + dy;
        if (x < 0 || y < 0 || x > GDT_COORD_MAX || y > GDT_COORD_MAX) {
            st = gdt_error_set(err, GDT_EINPUT, 3811,
                               "the cloud spans more than 2^31 - 1 lattice steps on an axis "
                               "(point at %lld, %lld from its corner), more than the seam "
                               "merge handles",
                               (long long)x, (long long)y);
            goto fail;
        }
        if (grow(&s->v, &s->cap_v, s->nv + 1, sizeof *s->v) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        s->v[s->nv].id = id_base + i;
        s->v[s->nv].x = x;
        s->v[s->nv].y = y;
        s->v[s->nv].z = z != NULL ? z[i] : 0.0;
        s->nv++;
    }
    if (s->ne > e0)
        qsort(s->e + e0, s->ne - e0, sizeof *s->e, cmp_edge);
fail:
    free(in_u);
    return st;
}
