/* gcd_phase2.c — Phase 2: the triangulation dual to the digital Voronoi
 * diagram (kernels/gcd_dual.cl), surrounded by the fake boundary
 * (gcd_hull.c, on the host like the paper's boundary walk), then linked in
 * parallel (kernels/gcd_mesh.cl).
 *
 * After this phase the live triangles form a valid triangulation of the
 * kept points (at their texel corners, d_pos), the frame vertices and the
 * fakes, whose outer boundary is the fake polygon; the triangles without a
 * fake vertex triangulate the frame rectangle (Cao, Edelsbrunner, Tan).
 * Interleaved with the dual triangles, chunk by chunk, are two dead slots
 * per missing point (gcd_geom.clh): Phase 4 fills them, so the triangles
 * it makes lie next to their neighbours in memory and Phase 5 needs no
 * sort. */
#include "private/gcd_ctx.h"
#include "private/gcd_hull.h"

#include <stdlib.h>
#include <string.h>

#include "gcd_geom.clh"

gdt_status gcd_link_start(gdt_core *c, gcd_run *r, gdt_error *err)
{
    if (gcd_buf_need(c, &c->d_cnt, 4 * r->nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_vt, 4 * r->nv, err) != GDT_OK ||
        gcd_fill(c, &c->d_cnt, r->nv, 0, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

gdt_status gcd_link_all(gdt_core *c, gcd_run *r, size_t counted, gdt_error *err)
{
    uint32_t total = 0;
    size_t T = r->ntris, nv = r->nv;

    if (gcd_buf_need(c, &c->d_aux2, 12 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux3, 12 * T, err) != GDT_OK ||
        gcd_args(c->k.m_vcount, err, "buub", &c->d_tri, (unsigned)counted, (unsigned)T,
                 &c->d_cnt) != GDT_OK ||
        gcd_launch(c, c->k.m_vcount, T - counted, err) != GDT_OK ||
        gcd_scan(c, &c->d_cnt, nv, &total, err) != GDT_OK ||
        gcd_args(c->k.m_vfill, err, "bubbb", &c->d_tri, (unsigned)T, &c->d_cnt, &c->d_aux2,
                 &c->d_aux3) != GDT_OK ||
        gcd_launch(c, c->k.m_vfill, T, err) != GDT_OK ||
        gcd_args(c->k.m_vt_min, err, "bbub", &c->d_cnt, &c->d_aux2, (unsigned)nv, &c->d_vt) !=
            GDT_OK ||
        gcd_launch(c, c->k.m_vt_min, nv, err) != GDT_OK ||
        gcd_fill(c, &c->d_opp, 3 * T, GCD_EMPTY, err) != GDT_OK ||
        gcd_args(c->k.m_link, err, "bubbbb", &c->d_tri, (unsigned)T, &c->d_cnt, &c->d_aux2,
                 &c->d_aux3, &c->d_opp) != GDT_OK ||
        gcd_launch(c, c->k.m_link, T, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

gdt_status gcd_phase2(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t nchunks = gcd_corner_chunks(r->W, r->H);
    size_t nf = r->nframe, nring = 0, nslots = 0, ndual = 0;
    uint32_t total = 0;
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
        gcd_buf_need(c, &c->d_opp, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_rslot, 8 * r->n + 8, err) != GDT_OK ||
        gcd_link_start(c, r, err) != GDT_OK)
        return err->status;
    /* dual triangles and reserved slots, chunk by chunk */
    if (nchunks > 0) {
        if (gcd_buf_need(c, &c->d_flags, 4 * nchunks, err) != GDT_OK ||
            gcd_args(c->k.p2_count, err, "buubb", GCD_COLOUR(c), r->W, r->H, &c->d_mrange,
                     &c->d_flags) != GDT_OK ||
            gcd_launch(c, c->k.p2_count, nchunks, err) != GDT_OK ||
            gcd_scan(c, &c->d_flags, nchunks, &total, err) != GDT_OK)
            return err->status;
        nslots = total;
        if (nslots < 2 * r->nmissing || nslots + nf + GCD_NFAKE > r->cap_tris)
            return gdt_error_set(err, GDT_EINTERNAL, 7622,
                                 "the dual has %zu slots for %zu vertices, %zu missing", nslots,
                                 r->nv, r->nmissing);
        ndual = nslots - 2 * r->nmissing;
        if (nslots > 0 &&
            (gcd_args(c->k.p2_write, err, "bbuubbubbb", GCD_COLOUR(c), &c->d_seed, r->W, r->H,
                      &c->d_flags, &c->d_mrange, (unsigned)r->kept, &c->d_tri, &c->d_rslot,
                      &c->d_cnt) != GDT_OK ||
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
    if (ndual + extra.n != 2 * (r->nv - r->nmissing) - GCD_NFAKE - 2) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7622,
                           "phase 2 made %zu dual and %zu ring triangles for %zu vertices", ndual,
                           extra.n, r->nv - r->nmissing);
        goto fail;
    }
    st = gdt_ocl_write(c->ocl, c->d_tri.b, 12 * nslots, extra.v, 12 * extra.n, err);
    if (st != GDT_OK)
        goto fail;
    r->ntris = nslots + extra.n;
    if (nchunks == 0 && r->nmissing > 0) {
        /* no corners: every point is missing; its slots go at the end */
        if (r->ntris + 2 * r->nmissing > r->cap_tris) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7622, "no room for %zu missing points",
                               r->nmissing);
            goto fail;
        }
        if (gcd_args(c->k.m_slots_seq, err, "uuubb", (unsigned)r->kept, (unsigned)r->nmissing,
                     (unsigned)r->ntris, &c->d_tri, &c->d_rslot) != GDT_OK ||
            gcd_launch(c, c->k.m_slots_seq, r->nmissing, err) != GDT_OK) {
            st = err->status;
            goto fail;
        }
        r->ntris += 2 * r->nmissing;
    }
    if (r->st != NULL) {
        r->st->dual_triangles = ndual;
        r->st->fake_triangles = nring;
    }
    st = gcd_link_all(c, r, nslots, err);
fail:
    gcd_tri_list_free(&extra);
    free(cycle);
    free(cpos);
    return st;
}
