/* gcd_phase34.c — Phases 3 (shift, delete) and 4 (insert) of the gCD core:
 * the host side only sizes the lists and launches the rounds of
 * kernels/gcd_shift.cl and kernels/gcd_insert.cl. */
#include "private/gcd_ctx.h"

#include <stdlib.h>
#include <string.h>

#define P3_MAX_ROUNDS 100000u
#define P4_MAX_ROUNDS 100000u

/* Reads and clears nothing: a device error counter pair (count, value). */
static gdt_status check_err(gdt_core *c, gcd_buf *stat, size_t ic, size_t iv, int code,
                            const char *what, gdt_error *err)
{
    uint32_t v[2];
    if (gdt_ocl_read(c->ocl, stat->b, 4 * ic, &v[0], 4, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, stat->b, 4 * iv, &v[1], 4, err) != GDT_OK)
        return err->status;
    if (v[0] != 0)
        return gdt_error_set(err, GDT_EINTERNAL, code, "%s (%u times, vertex %u)", what, v[0],
                             v[1]);
    return GDT_OK;
}

/* vt entries of the vertices of the triangles listed in d_list3[0..m). */
static gdt_status fix_vt(gdt_core *c, gcd_run *r, size_t m, gdt_error *err)
{
    if (m == 0)
        return GDT_OK;
    if (gcd_args(c->k.m_fix_vt_collect, err, "bbubb", &c->d_tri, &c->d_list3, (unsigned)m,
                 &c->d_vt, &c->d_vnew) != GDT_OK ||
        gcd_launch(c, c->k.m_fix_vt_collect, m, err) != GDT_OK ||
        gcd_args(c->k.m_fix_vt_apply, err, "bbubb", &c->d_tri, &c->d_list3, (unsigned)m,
                 &c->d_vt, &c->d_vnew) != GDT_OK ||
        gcd_launch(c, c->k.m_fix_vt_apply, m, err) != GDT_OK)
        return err->status;
    (void)r;
    return GDT_OK;
}

gdt_status gcd_phase3(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t nl = 0, nd = 0;
    uint32_t round = 1, cnt;
    uint64_t rounds = 0;
    uint32_t stat[4];

    if (gcd_buf_need(c, &c->d_chk, 4 * r->nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_stat34, 64, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_flags, 4 * r->nv, err) != GDT_OK ||
        gcd_fill(c, &c->d_chk, r->nv, GCD_EMPTY, err) != GDT_OK ||
        gcd_fill(c, &c->d_stat34, 16, 0, err) != GDT_OK)
        return err->status;

    /* Bulk shifting, then Algorithm 1 over the kept points left out. */
    if (r->kept > 0) {
        uint32_t ndrop = 0;
        uint64_t passes = 0;
        if (gcd_buf_need(c, &c->d_inm, 4 * r->kept, err) != GDT_OK ||
            gcd_buf_need(c, &c->d_inm2, 4 * r->kept, err) != GDT_OK ||
            gcd_buf_need(c, &c->d_dropped, 4 * r->kept, err) != GDT_OK ||
            gcd_buf_need(c, &c->d_list2, 4 * r->kept, err) != GDT_OK ||
            gcd_buf_need(c, &c->d_next, 4 * r->kept, err) != GDT_OK ||
            gcd_fill(c, &c->d_inm, r->kept, 1, err) != GDT_OK ||
            gcd_fill(c, &c->d_dropped, r->kept, 0, err) != GDT_OK)
            return err->status;
        do {
            uint32_t pass = (uint32_t)++passes;
            if (passes > P3_MAX_ROUNDS)
                return gdt_error_set(err, GDT_EINTERNAL, 7631, "bulk shifting did not end");
            if (gdt_ocl_copy(c->ocl, c->d_inm.b, 0, c->d_inm2.b, 0, 4 * r->kept, err) != GDT_OK ||
                gcd_fill(c, &c->d_small1, 1, 0, err) != GDT_OK)
                return err->status;
            if (pass == 1) {
                if (gcd_args(c->k.p3_bulk_check, err, "bubbillbbbubb", &c->d_tri,
                             (unsigned)r->ntris, &c->d_pos, &c->d_pts, (int)r->n, r->cx, r->cy,
                             &c->d_inm, &c->d_inm2, &c->d_dropped, pass, &c->d_next,
                             &c->d_small1) != GDT_OK ||
                    gcd_launch(c, c->k.p3_bulk_check, r->ntris, err) != GDT_OK)
                    return err->status;
            } else if (gcd_args(c->k.p3_bulk_star, err, "bbbbbillbbbububb", &c->d_tri,
                                &c->d_opp, &c->d_vt, &c->d_pos, &c->d_pts, (int)r->n, r->cx,
                                r->cy, &c->d_inm, &c->d_inm2, &c->d_dropped, pass, &c->d_list2,
                                ndrop, &c->d_next, &c->d_small1) != GDT_OK ||
                       gcd_launch(c, c->k.p3_bulk_star, ndrop, err) != GDT_OK) {
                return err->status;
            }
            if (gcd_read_u32(c, &c->d_small1, 0, &ndrop, err) != GDT_OK)
                return err->status;
            gcd_buf tmp = c->d_inm;
            c->d_inm = c->d_inm2;
            c->d_inm2 = tmp;
            tmp = c->d_list2;
            c->d_list2 = c->d_next;
            c->d_next = tmp;
        } while (ndrop > 0);
        if (r->st != NULL)
            r->st->shift_iterations += passes;
        if (gcd_args(c->k.p3_bulk_apply, err, "bbubbbb", &c->d_pos, &c->d_pts, (unsigned)r->kept,
                     &c->d_inm, &c->d_chk, &c->d_flags, &c->d_stat34) != GDT_OK ||
            gcd_launch(c, c->k.p3_bulk_apply, r->kept, err) != GDT_OK ||
            gcd_compact(c, &c->d_flags, r->kept, &c->d_list2, &nl, err) != GDT_OK ||
            gcd_buf_need(c, &c->d_next, 4 * (nl + 1), err) != GDT_OK)
            return err->status;
    }
    while (nl > 0) {
        if (++rounds > P3_MAX_ROUNDS)
            return gdt_error_set(err, GDT_EINTERNAL, 7631, "shifting did not end");
        if (gcd_fill(c, &c->d_small1, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p3_shift, err, "bbbbbillbububbbb", &c->d_tri, &c->d_opp, &c->d_pos,
                     &c->d_pts, &c->d_vt, (int)r->n, r->cx, r->cy, &c->d_list2, (unsigned)nl,
                     &c->d_chk, round, &c->d_bad, &c->d_next, &c->d_small1,
                     &c->d_stat34) != GDT_OK ||
            gcd_launch(c, c->k.p3_shift, nl, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small1, 0, &cnt, err) != GDT_OK)
            return err->status;
        if (cnt == nl)
            return gdt_error_set(err, GDT_EINTERNAL, 7631, "shifting round %u made no progress",
                                 round);
        nl = cnt;
        round++;
        gcd_buf tmp = c->d_list2;
        c->d_list2 = c->d_next;
        c->d_next = tmp;
    }
    if (check_err(c, &c->d_stat34, 2, 3, 7632, "a star walk of phase 3 failed", err) != GDT_OK)
        return err->status;
    if (r->st != NULL)
        r->st->shift_iterations += rounds;

    /* Algorithm 2: bad cases and the frame. */
    if (gcd_args(c->k.p3_del_flags, err, "buuub", &c->d_bad, (unsigned)r->n,
                 (unsigned)r->frame_base, (unsigned)r->nv, &c->d_flags) != GDT_OK ||
        gcd_launch(c, c->k.p3_del_flags, r->nv, err) != GDT_OK ||
        gcd_compact(c, &c->d_flags, r->nv, &c->d_list2, &nd, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_next, 4 * (nd + 1), err) != GDT_OK ||
        gcd_buf_need(c, &c->d_deg, 4 * (nd + 1), err) != GDT_OK ||
        gcd_buf_need(c, &c->d_off, 4 * (nd + 1), err) != GDT_OK ||
        gcd_buf_need(c, GCD_WIN(c), 4 * (nd + 1), err) != GDT_OK ||
        gcd_buf_need(c, &c->d_list3, 4 * r->cap_tris, err) != GDT_OK)
        return err->status;
    rounds = 0;
    while (nd > 0) {
        uint32_t total = 0, nnew = 0, nnext = 0;
        round = r->epoch++;
        if (++rounds > P3_MAX_ROUNDS)
            return gdt_error_set(err, GDT_EINTERNAL, 7633, "deleting did not end");
        if (gcd_args(c->k.p3_del_deg, err, "bbbbubb", &c->d_tri, &c->d_opp, &c->d_vt,
                     &c->d_list2, (unsigned)nd, &c->d_deg, &c->d_stat34) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_deg, nd, err) != GDT_OK ||
            gdt_ocl_copy(c->ocl, c->d_deg.b, 0, c->d_off.b, 0, 4 * nd, err) != GDT_OK ||
            gcd_scan(c, &c->d_off, nd, &total, err) != GDT_OK)
            return err->status;
        if (gcd_buf_need(c, &c->d_sc, 32 * (size_t)total + 32, err) != GDT_OK ||
            gcd_args(c->k.p3_del_mark, err, "bbbbubbb", &c->d_tri, &c->d_opp, &c->d_vt,
                     &c->d_list2, (unsigned)nd, &c->d_off, &c->d_sc, &c->d_mark) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_mark, nd, err) != GDT_OK ||
            gcd_args(c->k.p3_del_win, err, "bubbbbb", &c->d_list2, (unsigned)nd, &c->d_off,
                     &c->d_deg, &c->d_sc, &c->d_mark, GCD_WIN(c)) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_win, nd, err) != GDT_OK ||
            gcd_fill(c, &c->d_small1, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p3_del_apply, err, "bbbillbubbbbbbubbbbb", &c->d_tri, &c->d_opp,
                     &c->d_pos, (int)r->n, r->cx, r->cy, &c->d_list2, (unsigned)nd, &c->d_off,
                     &c->d_deg, GCD_WIN(c), &c->d_sc, GCD_EXCH(c), &c->d_flipped, round,
                     &c->d_vt, &c->d_rslot, &c->d_list3, &c->d_small1, &c->d_stat34) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_apply, nd, err) != GDT_OK ||
            gcd_args(c->k.p3_del_link, err, "bbbuubbbb", &c->d_opp, GCD_EXCH(c), &c->d_flipped,
                     round, (unsigned)nd, &c->d_off, &c->d_deg, GCD_WIN(c), &c->d_sc) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_link, nd, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small1, 0, &nnew, err) != GDT_OK ||
            fix_vt(c, r, nnew, err) != GDT_OK ||
            gcd_fill(c, &c->d_small2, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p3_del_next, err, "bubbbbbbb", &c->d_list2, (unsigned)nd, &c->d_off,
                     &c->d_deg, GCD_WIN(c), &c->d_sc, &c->d_mark, &c->d_next,
                     &c->d_small2) != GDT_OK ||
            gcd_launch(c, c->k.p3_del_next, nd, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small2, 0, &nnext, err) != GDT_OK)
            return err->status;
        if (check_err(c, &c->d_stat34, 2, 3, 7634, "a deletion of phase 3 failed", err) != GDT_OK)
            return err->status;
        if (nnext == nd)
            return gdt_error_set(err, GDT_EINTERNAL, 7633, "deletion round %u made no progress",
                                 round);
        nd = nnext;
        gcd_buf tmp = c->d_list2;
        c->d_list2 = c->d_next;
        c->d_next = tmp;
    }
    if (gdt_ocl_read(c->ocl, c->d_stat34.b, 0, stat, sizeof stat, err) != GDT_OK)
        return err->status;
    if (r->st != NULL) {
        r->st->delete_iterations += rounds;
        r->st->shifted += stat[0];
        r->st->bad_cases += stat[1];
    }
    return GDT_OK;
}

/* The missing points: Phase 1's (sharing a texel or on the frame) and
 * Phase 3's bad cases, i.e. every real point not in the triangulation. */
static gdt_status missing_list(gdt_core *c, gcd_run *r, size_t *nm, gdt_error *err)
{
    if (gcd_args(c->k.p4_absent_flags, err, "bbubub", &c->d_texel, &c->d_seed, (unsigned)r->n,
                 &c->d_bad, (unsigned)r->all_missing, &c->d_flags) != GDT_OK ||
        gcd_launch(c, c->k.p4_absent_flags, r->n, err) != GDT_OK ||
        gcd_compact(c, &c->d_flags, r->n, &c->d_list2, nm, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

gdt_status gcd_phase4(gdt_core *c, gcd_run *r, int flip_between, gdt_error *err)
{
    size_t nl = 0;
    uint64_t rounds = 0, flip_rounds = 0;
    uint32_t stat[6];

    if (missing_list(c, r, &nl, err) != GDT_OK)
        return err->status;
    if (r->st != NULL)
        r->st->inserted += nl;
    if (nl == 0)
        return GDT_OK;
    if (gcd_buf_need(c, &c->d_hint, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_next, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_hint2, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_cont, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_cont2, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_locep, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_locep2, 4 * nl, err) != GDT_OK ||
        gcd_fill(c, &c->d_locep, nl, 0, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_oldnb, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, GCD_WIN(c), 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_rank, 4 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_fix, 16 * nl, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_list3, 4 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_stat34, 64, err) != GDT_OK ||
        gcd_fill(c, &c->d_stat34, 16, 0, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_piv, 4 * nl, err) != GDT_OK ||
        gcd_args(c->k.p4_hints, err, "bubbbbuubb", &c->d_list2, (unsigned)nl, &c->d_texel,
                 &c->d_seed, &c->d_vt, &c->d_tri, (unsigned)r->ntris, (unsigned)r->all_missing,
                 &c->d_hint, &c->d_piv) != GDT_OK ||
        gcd_launch(c, c->k.p4_hints, nl, err) != GDT_OK)
        return err->status;
    if (flip_between && gcd_flip_prepare(c, r->cap_tris, err) != GDT_OK)
        return err->status;
    /* the flip counters share d_stat[0..3] with nothing here: Phase 4
     * keeps its own at d_stat[8..13] */
    while (nl > 0) {
        uint32_t nnew = 0, left = 0, round = r->epoch++;
        if (++rounds > P4_MAX_ROUNDS)
            return gdt_error_set(err, GDT_EINTERNAL, 7641, "inserting did not end");
        if (gcd_args(c->k.p4_locate, err, "bbbbillbubbbbbub", &c->d_tri, &c->d_opp, &c->d_pos,
                     &c->d_pts, (int)r->n, r->cx, r->cy, &c->d_list2, (unsigned)nl, &c->d_hint,
                     &c->d_piv, &c->d_cont, &c->d_locep, &c->d_flipped, round,
                     &c->d_stat34) != GDT_OK ||
            gcd_launch(c, c->k.p4_locate, nl, err) != GDT_OK ||
            gcd_args(c->k.p4_nb, err, "bubb", &c->d_opp, (unsigned)nl, &c->d_cont,
                     &c->d_oldnb) != GDT_OK ||
            gcd_launch(c, c->k.p4_nb, nl, err) != GDT_OK ||
            gdt_ocl_read(c->ocl, c->d_stat34.b, 0, stat, sizeof stat, err) != GDT_OK)
            return err->status;
        if (stat[2] != 0) {
            uint32_t a = stat[3], b = stat[4];
            /* report input indices */
            if (a < r->n && gcd_read_u32(c, &c->d_int2in, a, &a, err) != GDT_OK)
                return err->status;
            if (b < r->n && gcd_read_u32(c, &c->d_int2in, b, &b, err) != GDT_OK)
                return err->status;
            return gdt_error_set(err, GDT_EINPUT, 3602,
                                 "duplicate points: input points %u and %u are equal (%u "
                                 "duplicates found)",
                                 a < b ? a : b, a < b ? b : a, stat[2]);
        }
        if (stat[0] != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7642, "point location of point %u failed",
                                 stat[1]);
        if (gcd_args(c->k.p4_mark, err, "bbubb", &c->d_opp, &c->d_list2, (unsigned)nl,
                     &c->d_cont, &c->d_mark) != GDT_OK ||
            gcd_launch(c, c->k.p4_mark, nl, err) != GDT_OK ||
            gcd_args(c->k.p4_win, err, "bbubbb", &c->d_opp, &c->d_list2, (unsigned)nl,
                     &c->d_cont, &c->d_mark, GCD_WIN(c)) != GDT_OK ||
            gcd_launch(c, c->k.p4_win, nl, err) != GDT_OK ||
            gcd_fill(c, &c->d_small1, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p4_apply, err, "bbbbbubbbbbubbbb", &c->d_tri, &c->d_opp, &c->d_pos,
                     &c->d_pts, &c->d_list2, (unsigned)nl, &c->d_cont, GCD_WIN(c),
                     &c->d_rslot, GCD_EXCH(c), &c->d_flipped, round, &c->d_vt, &c->d_fix,
                     &c->d_list3, &c->d_small1) != GDT_OK ||
            gcd_launch(c, c->k.p4_apply, nl, err) != GDT_OK ||
            gcd_args(c->k.p4_link, err, "bbbuubb", &c->d_opp, GCD_EXCH(c), &c->d_flipped, round,
                     (unsigned)nl, GCD_WIN(c), &c->d_fix) != GDT_OK ||
            gcd_launch(c, c->k.p4_link, nl, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small1, 0, &nnew, err) != GDT_OK)
            return err->status;
        if (nnew == 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7641, "insertion round %u made no progress",
                                 round);
        /* no kernel reads vt after p4_hints: the entries of the vertices
         * around new triangles are repaired only for the phase check */
        if ((c->opts.check_phases && !flip_between && fix_vt(c, r, nnew, err) != GDT_OK) ||
            gcd_args(c->k.p4_unmark, err, "bubbbbb", &c->d_list2, (unsigned)nl, &c->d_cont,
                     &c->d_oldnb, &c->d_mark, GCD_WIN(c), &c->d_rank) != GDT_OK ||
            gcd_launch(c, c->k.p4_unmark, nl, err) != GDT_OK ||
            gcd_scan(c, &c->d_rank, nl, &left, err) != GDT_OK ||
            gcd_args(c->k.p4_compact, err, "bbbbububbbb", &c->d_list2, &c->d_hint, &c->d_cont,
                     &c->d_locep, (unsigned)nl, &c->d_rank, left, &c->d_next, &c->d_hint2,
                     &c->d_cont2, &c->d_locep2) != GDT_OK ||
            gcd_launch(c, c->k.p4_compact, nl, err) != GDT_OK)
            return err->status;
        if (flip_between) {
            /* gDel2D style: restore local optimality around the new
             * triangles, so the triangulation stays Delaunay and later
             * walks stay short. */
            uint64_t fr = 0;
            if (gcd_args(c->k.p5_from_list, err, "bubbu", &c->d_list3, nnew, &c->d_active,
                         &c->d_inact, r->epoch) != GDT_OK ||
                gcd_launch(c, c->k.p5_from_list, nnew, err) != GDT_OK ||
                gcd_flip_run(c, r, nnew, 0, &fr, err) != GDT_OK)
                return err->status;
            flip_rounds += fr;
        }
        nl = left;
        gcd_buf tmp = c->d_list2;
        c->d_list2 = c->d_next;
        c->d_next = tmp;
        tmp = c->d_hint;
        c->d_hint = c->d_hint2;
        c->d_hint2 = tmp;
        tmp = c->d_cont;
        c->d_cont = c->d_cont2;
        c->d_cont2 = tmp;
        tmp = c->d_locep;
        c->d_locep = c->d_locep2;
        c->d_locep2 = tmp;
    }
    if (gdt_ocl_read(c->ocl, c->d_stat34.b, 0, stat, sizeof stat, err) != GDT_OK)
        return err->status;
    if (r->st != NULL) {
        r->st->insert_iterations += rounds;
        r->st->walk_steps += stat[5];
        r->st->flip_iterations += flip_rounds;
    }
    if (flip_between) {
        uint32_t fs[4];
        if (gdt_ocl_read(c->ocl, c->d_stat.b, 0, fs, sizeof fs, err) != GDT_OK)
            return err->status;
        if (r->st != NULL) {
            r->st->edges_tested += fs[0];
            r->st->exact_escalations += fs[1];
            r->st->tiebreaks += fs[2];
            r->st->insert_flips += fs[3];
        }
    }
    return GDT_OK;
}
