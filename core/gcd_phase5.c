/* gcd_phase5.c — Phase 5: Lawson flipping with the exact in-circle and the
 * preferred-direction tie-break (kernels/gcd_flip.cl), until no edge needs
 * a flip: on CPU devices first block-local sequential passes
 * (local_flips), then the parallel rounds on whatever they left (on other
 * devices the rounds alone, from every slot).  The host only reads the
 * list lengths between launches. */
#include "private/gcd_ctx.h"
#include "private/gcd_test.h"

#include <stdlib.h>
#include <string.h>

/* Rounds after which flipping is declared stuck (a bug: Lawson's algorithm
 * with the tie-break terminates). */
#define P5_MAX_ROUNDS 1000000u

/* Block-local flipping: tests allowed per slot of a range before the rest
 * is left to the parallel rounds (about 3 are needed on terrain data; many
 * co-circular points need more), and most passes. */
#define P5_BUDGET 64u
#define P5_MAX_PASSES 64u

/* Counters read back each round (d_small1..3 on the device). */
enum { S_NCAND = 0, S_NEXACT = 1, S_NNEXT = 2 };

gdt_status gcd_run_buffers(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t T = r->cap_tris;
    if (gcd_buf_need(c, &c->d_inact, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_flipped, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, GCD_EXCH(c), 12 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_mark, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_stat, 64, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_bad, 4 * r->nv + 4, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_vnew, 4 * r->nv + 4, err) != GDT_OK ||
        gcd_fill(c, &c->d_bad, r->nv, 0, err) != GDT_OK ||
        gcd_fill(c, &c->d_vnew, r->nv, GCD_EMPTY, err) != GDT_OK ||
        gcd_fill(c, &c->d_inact, T, 0, err) != GDT_OK ||
        gcd_fill(c, &c->d_flipped, T, 0, err) != GDT_OK ||
        gcd_fill(c, &c->d_mark, T, GCD_EMPTY, err) != GDT_OK)
        return err->status;
    r->epoch = 1;
    return GDT_OK;
}

/* The candidate lists of a round hold one entry per tested edge: each
 * edge is tested once, so T slots give at most 3T/2 entries (8 bytes in
 * cand, 4 in exact).  p5_check and p5_exact only count what would not fit,
 * and gcd_flip_run reports it.  exact asks for 12 bytes per slot all the
 * same: on a CPU device only touched pages cost memory, and the larger
 * request makes the first flips reallocate it past Phase 1's texel array
 * (GCD_NEAR, every page touched), which lowers the peak RSS by that array
 * (65 MB for a 3.85M-point tile) where 6T would keep it. */
gdt_status gcd_flip_prepare(gdt_core *c, size_t T, gdt_error *err)
{
    if (gcd_buf_need(c, &c->d_vote, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_active, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_fnext, 4 * T, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_cand, 12 * T + 8, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_exact, 12 * T, err) != GDT_OK ||
        gcd_buf_need(c, GCD_WIN(c), 12 * T, err) != GDT_OK ||
        gcd_fill(c, &c->d_vote, T, GCD_EMPTY, err) != GDT_OK ||
        gcd_fill(c, &c->d_stat, 16, 0, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

gdt_status gcd_flip_run(gdt_core *c, gcd_run *r, size_t na0, int all_active, uint64_t *rounds,
                        gdt_error *err)
{
    size_t T = r->ntris, na = na0;
    uint32_t cnt[3];
    uint64_t nr = 0;
    size_t ccap = c->d_cand.cap / 8, xcap = c->d_exact.cap / 4;
    if (ccap > UINT32_MAX)
        ccap = UINT32_MAX;
    if (xcap > UINT32_MAX)
        xcap = UINT32_MAX;

    if (all_active) {
        na = T;
        if (gcd_args(c->k.p5_all, err, "ubbu", (unsigned)T, &c->d_active, &c->d_inact,
                     r->epoch) != GDT_OK ||
            gcd_launch(c, c->k.p5_all, T, err) != GDT_OK)
            return err->status;
    }
    while (na > 0) {
        uint32_t round = r->epoch;
        if (++nr > P5_MAX_ROUNDS)
            return gdt_error_set(err, GDT_EINTERNAL, 7651, "flipping did not end after %u rounds",
                                 P5_MAX_ROUNDS);
        if (gcd_fill(c, &c->d_small1, 1, 0, err) != GDT_OK ||
            gcd_fill(c, &c->d_small2, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p5_check, err, "bbbillbubuubbbbbbuu", &c->d_tri, &c->d_opp,
                     &c->d_pos, (int)r->n, r->cx, r->cy, &c->d_active, (unsigned)na,
                     &c->d_inact, round, (unsigned)(all_active && nr == 1), &c->d_vote,
                     &c->d_cand, &c->d_small1, &c->d_exact, &c->d_small2, &c->d_stat,
                     (unsigned)ccap, (unsigned)xcap) != GDT_OK ||
            gcd_launch(c, c->k.p5_check, na, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small2, 0, &cnt[S_NEXACT], err) != GDT_OK)
            return err->status;
        if (cnt[S_NEXACT] > xcap)
            return gdt_error_set(err, GDT_EINTERNAL, 7654,
                                 "%u edges for the exact test in a flipping round, room for %zu",
                                 cnt[S_NEXACT], xcap);
        if (cnt[S_NEXACT] > 0 &&
            (gcd_args(c->k.p5_exact, err, "bbbillbubbbbu", &c->d_tri, &c->d_opp, &c->d_pos,
                      (int)r->n, r->cx, r->cy, &c->d_exact, cnt[S_NEXACT], &c->d_vote,
                      &c->d_cand, &c->d_small1, &c->d_stat, (unsigned)ccap) != GDT_OK ||
             gcd_launch(c, c->k.p5_exact, cnt[S_NEXACT], err) != GDT_OK))
            return err->status;
        if (gcd_read_u32(c, &c->d_small1, 0, &cnt[S_NCAND], err) != GDT_OK)
            return err->status;
        if (cnt[S_NCAND] > ccap)
            return gdt_error_set(err, GDT_EINTERNAL, 7654,
                                 "%u flip candidates in a round, room for %zu", cnt[S_NCAND],
                                 ccap);
        r->epoch++;
        if (cnt[S_NCAND] == 0)
            break;
        if (gcd_args(c->k.p5_flip, err, "bbbubbbubb", &c->d_tri, &c->d_opp, &c->d_cand,
                     cnt[S_NCAND], &c->d_vote, GCD_EXCH(c), &c->d_flipped, round, GCD_WIN(c),
                     &c->d_stat) != GDT_OK ||
            gcd_launch(c, c->k.p5_flip, cnt[S_NCAND], err) != GDT_OK ||
            gcd_args(c->k.p5_link, err, "bbubbbu", &c->d_opp, &c->d_cand, cnt[S_NCAND],
                     GCD_WIN(c), GCD_EXCH(c), &c->d_flipped, round) != GDT_OK ||
            gcd_launch(c, c->k.p5_link, cnt[S_NCAND], err) != GDT_OK ||
            gcd_fill(c, &c->d_small3, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p5_next, err, "bubbubb", &c->d_cand, cnt[S_NCAND], &c->d_vote,
                     &c->d_inact, r->epoch, &c->d_fnext, &c->d_small3) != GDT_OK ||
            gcd_launch(c, c->k.p5_next, cnt[S_NCAND], err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small3, 0, &cnt[S_NNEXT], err) != GDT_OK)
            return err->status;
        na = cnt[S_NNEXT];
        gcd_buf tmp = c->d_active;
        c->d_active = c->d_fnext;
        c->d_fnext = tmp;
        if (na > T / 8) {
            /* a long list in scheduling order would scatter the next
             * round's reads: list the same triangles in index order */
            size_t nsorted = 0;
            if (gcd_buf_need(c, &c->d_flags, 4 * T, err) != GDT_OK ||
                gcd_args(c->k.p5_round_flags, err, "buub", &c->d_inact, (unsigned)T, r->epoch,
                         &c->d_flags) != GDT_OK ||
                gcd_launch(c, c->k.p5_round_flags, T, err) != GDT_OK ||
                gcd_compact(c, &c->d_flags, T, &c->d_active, &nsorted, err) != GDT_OK)
                return err->status;
            if (nsorted != na)
                return gdt_error_set(err, GDT_EINTERNAL, 7653,
                                     "active list of %zu triangles, %zu marked", na, nsorted);
        }
    }
    if (rounds != NULL)
        *rounds = nr;
    return GDT_OK;
}

/* Sorts the triangle list by smallest vertex (kernels/gcd_mesh.cl), dropping
 * dead slots: the flipping rounds then find neighbours and vertices near in
 * memory.  Scratch that is dead here: the permutation and its inverse go to
 * d_fnext and d_active (the flip lists, filled after gcd_flip_prepare), the
 * sorted triangles to d_aux2 and d_aux3 (Phase 2's), which then swap with
 * d_tri and d_opp. */
static gdt_status sort_tris(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t T = r->ntris, nv = r->nv;
    uint32_t live = 0;
    gcd_buf *perm = &c->d_fnext, *inv = &c->d_active, tmp;
    if (gcd_buf_need(c, &c->d_cnt, 4 * nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux, 4 * nv, err) != GDT_OK ||
        gcd_buf_need(c, perm, 4 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, inv, 4 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux2, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux3, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_fill(c, &c->d_cnt, nv, 0, err) != GDT_OK ||
        gcd_args(c->k.m_sort_count, err, "bub", &c->d_tri, (unsigned)T, &c->d_cnt) != GDT_OK ||
        gcd_launch(c, c->k.m_sort_count, T, err) != GDT_OK ||
        gdt_ocl_copy(c->ocl, c->d_cnt.b, 0, c->d_aux.b, 0, 4 * nv, err) != GDT_OK ||
        gcd_scan(c, &c->d_aux, nv, &live, err) != GDT_OK ||
        gcd_fill(c, &c->d_cnt, nv, 0, err) != GDT_OK ||
        gcd_args(c->k.m_sort_scatter, err, "bubbb", &c->d_tri, (unsigned)T, &c->d_aux, &c->d_cnt,
                 perm) != GDT_OK ||
        gcd_launch(c, c->k.m_sort_scatter, T, err) != GDT_OK ||
        gcd_args(c->k.m_sort_bucket, err, "bbub", &c->d_aux, &c->d_cnt, (unsigned)nv, perm) !=
            GDT_OK ||
        gcd_launch(c, c->k.m_sort_bucket, nv, err) != GDT_OK ||
        gcd_args(c->k.m_sort_inverse, err, "bub", perm, live, inv) != GDT_OK ||
        gcd_launch(c, c->k.m_sort_inverse, live, err) != GDT_OK ||
        gcd_args(c->k.m_sort_apply, err, "bbbbubb", &c->d_tri, &c->d_opp, perm, inv, live,
                 &c->d_aux2, &c->d_aux3) != GDT_OK ||
        gcd_launch(c, c->k.m_sort_apply, live, err) != GDT_OK ||
        gcd_args(c->k.m_sort_vt, err, "bubu", &c->d_vt, (unsigned)nv, inv, (unsigned)T) !=
            GDT_OK ||
        gcd_launch(c, c->k.m_sort_vt, nv, err) != GDT_OK)
        return err->status;
    r->ntris = live;
    tmp = c->d_tri;
    c->d_tri = c->d_aux2;
    c->d_aux2 = tmp;
    tmp = c->d_opp;
    c->d_opp = c->d_aux3;
    c->d_aux3 = tmp;
    return GDT_OK;
}

/* Block-local Lawson flipping (kernels/gcd_flip.cl: p5_local, then
 * p5_local_lists on the deferred slots, alternating the two partitions into
 * blocks) over the live slots; *na receives the slots left over, listed in
 * d_active and marked in d_inact with r->epoch (the first round of
 * gcd_flip_run). */
static gdt_status local_flips(gdt_core *c, gcd_run *r, size_t *na, gdt_error *err)
{
    size_t T = r->ntris, nb = c->flip_blocks;
    size_t bsize = (T + nb - 1) / nb;
    uint32_t nd = UINT32_MAX, prev = UINT32_MAX, round = r->epoch++;
    gcd_buf *lists[2] = {&c->d_fnext, &c->d_cand}, *counts[2] = {&c->d_nlist, &c->d_nlist2};
    size_t qcap = 8;
    if (bsize < c->flip_min_block)
        bsize = c->flip_min_block;
    nb = (T + bsize - 1) / bsize;
    /* room for a flip wave through the block, within the device's bound */
    while (2 * qcap <= c->flip_queue && qcap < 4 * bsize)
        qcap *= 2;
    if (gcd_buf_need(c, &c->d_queue, 4 * (nb + 1) * qcap, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_nlist, 4 * (nb + 1), err) != GDT_OK ||
        gcd_buf_need(c, &c->d_nlist2, 4 * (nb + 1), err) != GDT_OK ||
        gcd_args(c->k.p5_local, err, "bbbilluubuububbb", &c->d_tri, &c->d_opp, &c->d_pos,
                 (int)r->n, r->cx, r->cy, (unsigned)T, (unsigned)bsize, &c->d_queue,
                 (unsigned)qcap, P5_BUDGET, &c->d_inact, round, lists[0], counts[0],
                 &c->d_stat) != GDT_OK ||
        gcd_launch_wg(c, c->k.p5_local, nb, 1, err) != GDT_OK)
        return err->status;
    /* Later passes alternate the partitions while they at least halve the
     * deferred slots; then one work-item takes what is left (the chains of
     * flips that cross blocks, e.g. along the hull, whose ring triangles
     * are stored after all others). */
    for (unsigned pass = 1, whole = 0; pass <= P5_MAX_PASSES && !whole; pass++) {
        uint32_t next = r->epoch++;
        unsigned shift = pass & 1;
        whole = pass > 1 && 2 * (uint64_t)nd > prev;
        prev = nd;
        if (gcd_fill(c, &c->d_small3, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p5_local_lists, err, "bbbilluuuubuubuubbbbbbb", &c->d_tri,
                     &c->d_opp, &c->d_pos, (int)r->n, r->cx, r->cy, (unsigned)T,
                     (unsigned)bsize, shift, whole, &c->d_queue, (unsigned)qcap, P5_BUDGET,
                     &c->d_inact, round, next, lists[(pass + 1) & 1], counts[(pass + 1) & 1],
                     lists[pass & 1], counts[pass & 1], &c->d_active, &c->d_small3,
                     &c->d_stat) != GDT_OK ||
            gcd_launch_wg(c, c->k.p5_local_lists, whole ? 1 : nb + shift, 1, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small3, 0, &nd, err) != GDT_OK)
            return err->status;
        round = next;
        if (nd == 0)
            break;
    }
    r->epoch = round;
    *na = nd;
    return GDT_OK;
}

gdt_status gcd_phase5(gdt_core *c, gcd_run *r, gdt_error *err)
{
    uint64_t rounds = 0;
    uint32_t stat[4];
    if (r->sort_tris && sort_tris(c, r, err) != GDT_OK)
        return err->status;
    if (gcd_flip_prepare(c, r->cap_tris, err) != GDT_OK)
        return err->status;
    if (c->flip_blocks > 0 && r->ntris > 0) {
        size_t na = 0;
        if (local_flips(c, r, &na, err) != GDT_OK)
            return err->status;
        if (gcd_flip_run(c, r, na, 0, &rounds, err) != GDT_OK)
            return err->status;
    } else if (gcd_flip_run(c, r, 0, 1, &rounds, err) != GDT_OK) {
        return err->status;
    }
    if (gdt_ocl_read(c->ocl, c->d_stat.b, 0, stat, sizeof stat, err) != GDT_OK)
        return err->status;
    if (r->st != NULL) {
        r->st->flip_iterations += rounds;
        r->st->edges_tested += stat[0];
        r->st->exact_escalations += stat[1];
        r->st->tiebreaks += stat[2];
        r->st->flips += stat[3];
    }
    return GDT_OK;
}

gdt_status gcd_test_flip(gdt_core *c, gdt_mesh *m, gdt_core_stats *st, gdt_error *err)
{
    gcd_run r;
    int32_t *pos = NULL;
    gdt_status s = GDT_OK;

    memset(&r, 0, sizeof r);
    r.n = m->nverts;
    r.nv = m->nverts;
    r.ntris = m->ntris;
    r.cap_tris = m->ntris;
    r.st = st;
    if (m->ntris == 0)
        return GDT_OK;
    for (size_t i = 0; i < m->nverts; i++) {
        if (i == 0 || m->pts[i].x < r.xmin)
            r.xmin = m->pts[i].x;
        if (i == 0 || m->pts[i].x > r.xmax)
            r.xmax = m->pts[i].x;
        if (i == 0 || m->pts[i].y < r.ymin)
            r.ymin = m->pts[i].y;
        if (i == 0 || m->pts[i].y > r.ymax)
            r.ymax = m->pts[i].y;
    }
    r.cx = r.xmin + (r.xmax - r.xmin) / 2;
    r.cy = r.ymin + (r.ymax - r.ymin) / 2;
    pos = malloc(8 * m->nverts);
    if (pos == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < m->nverts; i++) {
        pos[2 * i] = (int32_t)m->pts[i].x;
        pos[2 * i + 1] = (int32_t)m->pts[i].y;
    }
    if (gcd_buf_need(c, &c->d_pos, 8 * m->nverts, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_tri, 12 * m->ntris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_opp, 12 * m->ntris, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_pos.b, 0, pos, 8 * m->nverts, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_tri.b, 0, m->tri, 12 * m->ntris, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_opp.b, 0, m->opp, 12 * m->ntris, err) != GDT_OK ||
        gcd_run_buffers(c, &r, err) != GDT_OK || gcd_phase5(c, &r, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_tri.b, 0, m->tri, 12 * m->ntris, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_opp.b, 0, m->opp, 12 * m->ntris, err) != GDT_OK)
        s = err->status;
    free(pos);
    return s;
}
