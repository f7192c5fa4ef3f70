/* gcd_phase2.c — Phase 2: the triangulation dual to the digital Voronoi
 * diagram (kernels/gcd_dual.cl), surrounded by the fake boundary
 * (gcd_hull.c, on the host like the paper's boundary walk), then linked in
 * parallel (kernels/gcd_mesh.cl).
 *
 * After this phase the live triangles form a valid triangulation of the
 * kept points (at their texel corners, d_pos), the frame vertices and the
 * fakes, whose outer boundary is the fake polygon; the triangles without a
 * fake vertex triangulate the frame rectangle (Cao, Edelsbrunner, Tan). */
#include "private/gcd_ctx.h"
#include "private/gcd_hull.h"

#include <stdlib.h>
#include <string.h>

#include "gcd_geom.clh"

#define P2_CHUNK 256u

gdt_status gcd_link_all(gdt_core *c, gcd_run *r, gdt_error *err)
{
    uint32_t total = 0;
    size_t T = r->ntris, nv = r->nv;

    if (gcd_buf_need(c, &c->d_cnt, 4 * nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux, 4 * nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux2, 12 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_vt, 4 * nv, err) != GDT_OK ||
        gcd_fill(c, &c->d_cnt, nv, 0, err) != GDT_OK ||
        gcd_args(c->k.m_vcount, err, "bub", &c->d_tri, (unsigned)T, &c->d_cnt) != GDT_OK ||
        gcd_launch(c, c->k.m_vcount, T, err) != GDT_OK ||
        gdt_ocl_copy(c->ocl, c->d_cnt.b, 0, c->d_aux.b, 0, 4 * nv, err) != GDT_OK ||
        gcd_scan(c, &c->d_aux, nv, &total, err) != GDT_OK ||
        gcd_fill(c, &c->d_cnt, nv, 0, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux3, 12 * T, err) != GDT_OK ||
        gcd_args(c->k.m_vfill, err, "bubbbb", &c->d_tri, (unsigned)T, &c->d_aux, &c->d_cnt,
                 &c->d_aux2, &c->d_aux3) != GDT_OK ||
        gcd_launch(c, c->k.m_vfill, T, err) != GDT_OK ||
        gcd_fill(c, &c->d_opp, 3 * T, GCD_EMPTY, err) != GDT_OK ||
        gcd_args(c->k.m_link, err, "bubbbbb", &c->d_tri, (unsigned)T, &c->d_aux, &c->d_cnt,
                 &c->d_aux2, &c->d_aux3, &c->d_opp) != GDT_OK ||
        gcd_launch(c, c->k.m_link, T, err) != GDT_OK ||
        gcd_fill(c, &c->d_vt, nv, GCD_EMPTY, err) != GDT_OK ||
        gcd_args(c->k.m_vt_min, err, "bub", &c->d_tri, (unsigned)T, &c->d_vt) != GDT_OK ||
        gcd_launch(c, c->k.m_vt_min, T, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

gdt_status gcd_phase2(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t ncorner = r->W >= 2 && r->H >= 2 ? (size_t)(r->W - 1) * (r->H - 1) : 0;
    size_t nchunks = (ncorner + P2_CHUNK - 1) / P2_CHUNK;
    size_t nf = r->nframe, nring = 0;
    uint32_t ndual = 0;
    int32_t *cycle = NULL;
    gdt_ipt *cpos = NULL;
    gcd_tri_list extra;
    gcd_frame fr;
    gdt_status st = GDT_OK;

    memset(&extra, 0, sizeof extra);
    fr.cx = r->cx;
    fr.cy = r->cy;
    fr.nreal = (int32_t)r->n;

    if (gcd_buf_need(c, &c->d_pos, 8 * r->nv, err) != GDT_OK ||
        gcd_args(c->k.m_snap, err, "bbbuiiib", &c->d_pts, &c->d_texel, &c->d_seed,
                 (unsigned)r->n, (int)r->xmin, (int)r->ymin, (int)r->cell, &c->d_pos) != GDT_OK ||
        gcd_launch(c, c->k.m_snap, r->n, err) != GDT_OK ||
        gcd_args(c->k.m_frame_pos, err, "uuiiiub", r->W, r->H, (int)r->xmin, (int)r->ymin,
                 (int)r->cell, (unsigned)r->frame_base, &c->d_pos) != GDT_OK ||
        gcd_launch(c, c->k.m_frame_pos, nf, err) != GDT_OK)
        return err->status;
    if (gcd_buf_need(c, &c->d_tri, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_opp, 12 * r->cap_tris, err) != GDT_OK)
        return err->status;
    if (nchunks > 0) {
        if (gcd_buf_need(c, &c->d_flags, 4 * nchunks, err) != GDT_OK ||
            gcd_args(c->k.p2_count, err, "buuub", &c->d_colour, r->W, r->H, P2_CHUNK,
                     &c->d_flags) != GDT_OK ||
            gcd_launch(c, c->k.p2_count, nchunks, err) != GDT_OK ||
            gcd_scan(c, &c->d_flags, nchunks, &ndual, err) != GDT_OK)
            return err->status;
        if ((size_t)ndual + nf + GCD_NFAKE > r->cap_tris)
            return gdt_error_set(err, GDT_EINTERNAL, 7622,
                                 "the dual has %u triangles for %zu vertices", ndual, r->nv);
        if (ndual > 0 &&
            (gcd_args(c->k.p2_write, err, "bbuuubb", &c->d_colour, &c->d_seed, r->W, r->H,
                      P2_CHUNK, &c->d_flags, &c->d_tri) != GDT_OK ||
             gcd_launch(c, c->k.p2_write, nchunks, err) != GDT_OK))
            return err->status;
    }

    /* The frame cycle, counter-clockwise (kernels/gcd_geom.clh). */
    cycle = malloc(nf * sizeof *cycle);
    cpos = malloc(nf * sizeof *cpos);
    if (cycle == NULL || cpos == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (size_t k = 0; k < nf; k++) {
        uint32_t t = gcd_frame_texel((gcd_u32)k, r->W, r->H);
        cycle[k] = (int32_t)(r->frame_base + k);
        cpos[k].x = r->xmin + (int64_t)(t % r->W) * r->cell;
        cpos[k].y = r->ymin + (int64_t)(t / r->W) * r->cell;
    }
    if (r->W >= 2 && r->H >= 2)
        st = gcd_ring(&fr, cycle, cpos, nf, &extra, &nring, err);
    else
        st = gcd_hull_degenerate(&fr, cycle, cpos, nf, &extra, &nring, err);
    if (st != GDT_OK)
        goto fail;
    if ((size_t)ndual + extra.n != 2 * (r->nv - r->nmissing) - GCD_NFAKE - 2) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7622,
                           "phase 2 made %u dual and %zu ring triangles for %zu vertices", ndual,
                           extra.n, r->nv - r->nmissing);
        goto fail;
    }
    st = gdt_ocl_write(c->ocl, c->d_tri.b, 12 * (size_t)ndual, extra.v, 12 * extra.n, err);
    if (st != GDT_OK)
        goto fail;
    r->ntris = (size_t)ndual + extra.n;
    if (r->st != NULL) {
        r->st->dual_triangles = ndual;
        r->st->fake_triangles = nring;
    }
    st = gcd_link_all(c, r, err);
fail:
    gcd_tri_list_free(&extra);
    free(cycle);
    free(cpos);
    return st;
}
