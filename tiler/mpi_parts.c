/* mpi_parts.c — the mesh written by the tiles' owners under mpirun (see
 * private/mpi_sched.h and, for the file layout, private/tiled_out.h).
 *
 * Protocol:
 *   GO (mpi_run.c) ends with the layout: whether the mesh is written in
 *   parts, then the temporary's path, the header's length, the vertex
 *   count and the lattice; each rank opens its part;
 *   during the tile stage each rank writes the vertices of each of its
 *   tiles as the tile is finished or reused (their places, base[k], are
 *   known from pass 2), so that the disk works beside the tiles;
 *   tile k's faces start at the sum of the kept faces of the tiles before
 *   it, known once they are all done: as the prefix of done tiles grows,
 *   rank 0 reads the face count of each tile that joined it from its .tri
 *   file, writes the faces of its own such tiles and sends FPLACE to the
 *   owners of the others (pairs of tile and first face), which write them
 *   between their tiles (mr_parts_advance, mr_parts_place).  The owners
 *   of the tile stage are spread over tile order (mr_tile_owners), so the
 *   prefix grows all through the stage and most faces are written beside
 *   it, as in a single process.  Not for a text mesh, whose records have
 *   no fixed size, nor with --concavity, whose drops the merge decides;
 *   after every rank's FINISHED, when the job has not failed, rank 0 reads
 *   the face counts of the tiles not yet placed and sends PARTS to every
 *   other rank: a status, then (when it is GDT_OK) every tile's first face
 *   (ntiles + 1 prefix sums);
 *   each rank writes the faces of its tiles not written yet, syncs its
 *   part and answers WROTE: its status (the first failure of any of its
 *   writes), the seconds it spent writing its part, its message, its
 *   tiles' face counts and drops, and how many of its tiles FPLACE placed;
 *   rank 0 writes its own tiles' remaining faces meanwhile, finishes the
 *   seam merge, waits for every WROTE and completes the file with the
 *   merge's faces.
 * A text mesh (OBJ, LandXML; m->part_text) goes through fragments
 * (private/tiled_out.h): during the tile stage each rank formats each of
 * its tiles' vertices, and faces unless --concavity, into fragments; after
 * PARTS it makes the missing face fragments and answers TSIZES (status,
 * then for each of its tiles: the tile, its vertex bytes, its face bytes);
 * rank 0, having made its own, gathers every TSIZES, lays the tiles'
 * fragments out in tile order and answers each rank TPLACE (whether to
 * place: no when any rank failed; for each of its tiles where its vertex
 * bytes and its face bytes begin); each rank places its fragments, then
 * syncs and answers WROTE as above.
 * With a DEM (m->part_dem; GO carries rank 0's grid) each other rank
 * rasterises its tiles' kept faces into windows as it writes them
 * (private/tiled_dem.h), saved before its WROTE; rank 0 puts a rank's
 * windows into its writer when that WROTE arrives.
 * A failed PARTS (rank 0 could not read a tile's count) asks nothing: the
 * ranks wait for FINAL as before.  Every record has the place and bytes
 * of the sequential writer's, so the file is the same for any rank count. */
#include "private/mpi_sched.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_cloud.h"
#include "private/run_stats.h"
#include "private/tiled_dem.h"
#include "private/tiled_files.h"
#include "private/tiled_out.h"

/* What tr_out needs of the run to write tiles in parts. */
static void part_src(const tr_run *c, const gdt_lattice *lat, tr_out_src *s)
{
    memset(s, 0, sizeof *s);
    s->output = c->opts->output;
    s->meta.lattice = *lat;
    s->tiler = c->tiler;
    s->tiles_dir = c->tiles_dir;
    s->job = c->job;
    s->base = c->base;
    s->ntiles = gdt_tiler_tile_count(c->tiler);
    s->stop = c->opts->stop;
    s->trim = gdt_trim_on(&c->trim);
    s->concavity = c->trim.concavity > 0;
    s->tri_cached = c->tri_cached;
}

/* Keeps the first failure of this rank's writes. */
static void part_fail(mr_ctx *m, gdt_status st, const gdt_error *err)
{
    if (st != GDT_OK && m->part_st == GDT_OK) {
        m->part_st = st;
        m->part_err = *err;
    }
}

void mr_parts_pack_layout(mr_ctx *m, gdt_pack *p)
{
    tr_run *c = m->c;
    const char *tmp = NULL;
    uint64_t header = 0, nvert = 0;
    const gdt_lattice *lat;

    gdt_pack_u64(p, (uint64_t)(c->out_parts != 0));
    if (!c->out_parts)
        return;
    m->part_text = tr_out_text(c->out);
    m->placing = !m->part_text && !(c->trim.concavity > 0);
    gdt_pack_u64(p, (uint64_t)m->part_text);
    /* with a DEM, its grid: the other ranks rasterise their tiles on it */
    m->part_dem = c->dem != NULL;
    gdt_pack_u64(p, (uint64_t)m->part_dem);
    if (m->part_dem) {
        const gdt_raster_grid *g = tr_dem_grid(c->dem);
        gdt_pack_bytes(p, g, sizeof *g); /* the same build on every rank */
    }
    lat = &gdt_cloud_get_info(c->cloud)->lattice;
    tr_out_parts_layout(c->out, &tmp, &header, &nvert);
    gdt_pack_bytes(p, tmp, strlen(tmp));
    gdt_pack_u64(p, header);
    gdt_pack_u64(p, nvert);
    gdt_pack_f64(p, lat->sx);
    gdt_pack_f64(p, lat->sy);
    gdt_pack_f64(p, lat->ox);
    gdt_pack_f64(p, lat->oy);
}

gdt_status mr_parts_read_layout(mr_ctx *m, gdt_unpack *u, gdt_error *err)
{
    size_t tl = 0;
    const unsigned char *tmp;

    m->parts = gdt_unpack_u64(u) != 0;
    if (!m->parts)
        return u->bad ? mr_bad_message(0, TAG_GO, err) : GDT_OK;
    m->part_text = gdt_unpack_u64(u) != 0;
    m->part_dem = gdt_unpack_u64(u) != 0;
    if (m->part_dem) {
        size_t gl = 0;
        const unsigned char *g = gdt_unpack_bytes(u, &gl);
        if (g == NULL || gl != sizeof m->part_grid)
            return mr_bad_message(0, TAG_GO, err);
        memcpy(&m->part_grid, g, sizeof m->part_grid);
    }
    tmp = gdt_unpack_bytes(u, &tl);
    m->part_header = gdt_unpack_u64(u);
    m->part_nvert = gdt_unpack_u64(u);
    m->part_lattice.sx = gdt_unpack_f64(u);
    m->part_lattice.sy = gdt_unpack_f64(u);
    m->part_lattice.ox = gdt_unpack_f64(u);
    m->part_lattice.oy = gdt_unpack_f64(u);
    if (u->bad || tmp == NULL)
        return mr_bad_message(0, TAG_GO, err);
    free(m->part_path);
    m->part_path = malloc(tl + 1);
    if (m->part_path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memcpy(m->part_path, tmp, tl);
    m->part_path[tl] = '\0';
    return GDT_OK;
}

gdt_status mr_parts_open(mr_ctx *m, gdt_error *err)
{
    tr_out_src src;
    gdt_status st = GDT_OK;
    part_src(m->c, &m->part_lattice, &src);
    if (m->part_dem && m->part_windows == NULL)
        st = tr_dem_create_windows(&m->part_windows, &m->part_grid, err);
    src.dem = m->part_windows;
    if (st == GDT_OK)
        st = tr_out_open_part(&m->part_out, &src, m->part_path, m->part_header, m->part_nvert, err);
    return st;
}

/* Rank 0: the DEM windows of rank from's tiles into the DEM, each file
 * removed once its cells are in. */
static gdt_status take_windows(mr_ctx *m, int from, gdt_error *err)
{
    tr_run *c = m->c;
    gdt_status st = GDT_OK;
    for (uint64_t k = 0; st == GDT_OK && k < m->ntiles; k++) {
        gdt_tile_desc d;
        char *path = NULL;
        if (m->towner[k] != from)
            continue;
        st = gdt_tiler_tile_info(c->tiler, k, &d, err);
        if (st == GDT_OK)
            st = tr_tile_path(c->tiles_dir, &d, "dwin", &path, err);
        if (st == GDT_OK)
            st = tr_dem_window_put(c->dem, path, err);
        if (st == GDT_OK)
            unlink(path);
        free(path);
    }
    return st;
}

void mr_parts_tile_done(mr_ctx *m, uint64_t k)
{
    tr_out *o = m->rank == 0 ? (m->c->out_parts ? m->c->out : NULL) : m->part_out;
    gdt_error e;
    double t0;
    if (o == NULL || m->part_st != GDT_OK)
        return;
    gdt_error_clear(&e);
    t0 = gdt_now();
    part_fail(m, tr_out_write_vertices(o, k, &e), &e);
    /* a text mesh: the faces' fragment now as well (its place is not
     * needed yet), unless --concavity's peel decides them; a PLY's faces
     * wait for their place (mr_parts_advance) */
    if (m->part_text && m->part_st == GDT_OK && !(m->c->trim.concavity > 0))
        part_fail(m, tr_out_write_faces(o, k, 0, &e), &e);
    m->part_t += gdt_now() - t0;
}

/* Most bytes of one FPLACE message (128 pairs).  Rank 0 sends them while
 * another rank may be sending it RECORD: small messages leave a blocking
 * send as soon as the transport has buffered them (Open MPI's eager
 * protocol, from 4 KiB up on every transport), so neither waits for the
 * other's receive. */
#define FPLACE_BYTES 2048

/* Rank 0: m->first and m->fwritten for every tile (first[0] = 0).
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
static gdt_status need_places(mr_ctx *m, gdt_error *err)
{
    if (m->first == NULL && (m->first = calloc(m->ntiles + 1, sizeof *m->first)) == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (m->fwritten == NULL && (m->fwritten = calloc(m->ntiles + 1, 1)) == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}

void mr_parts_advance(mr_ctx *m)
{
    tr_run *c = m->c;
    gdt_pack *to = NULL; /* FPLACE for each rank */
    gdt_status st = GDT_OK;
    gdt_error e;
    double t0;

    if (!m->placing || m->fplaced >= m->prefix || c->out == NULL)
        return;
    gdt_error_clear(&e);
    if (m->part_st != GDT_OK || m->job_st != GDT_OK) {
        m->placing = 0; /* the job fails: nothing more is placed */
        return;
    }
    t0 = gdt_now();
    st = need_places(m, &e);
    if (st == GDT_OK && (to = calloc((size_t)m->size, sizeof *to)) == NULL)
        st = gdt_error_set(&e, GDT_EINTERNAL, 7001, "out of memory");
    while (st == GDT_OK && m->fplaced < m->prefix) {
        uint64_t k = m->fplaced, kept = 0;
        int r = m->towner[k];
        st = tr_out_count_faces(c->out, k, &kept, NULL, NULL, NULL, &e);
        if (st != GDT_OK)
            break;
        m->first[k + 1] = m->first[k] + kept;
        m->fplaced++;
        if (r == 0) {
            st = tr_out_write_faces(c->out, k, m->first[k], &e);
            m->fwritten[k] = st == GDT_OK;
        } else {
            gdt_pack_u64(&to[r], k);
            gdt_pack_u64(&to[r], m->first[k]);
            if (to[r].n >= FPLACE_BYTES)
                st = mr_send_pack(m, r, TAG_FPLACE, &to[r], &e);
        }
    }
    for (int r = 1; to != NULL && r < m->size; r++) {
        if (to[r].n == 0 && !to[r].oom)
            continue;
        if (st == GDT_OK)
            st = mr_send_pack(m, r, TAG_FPLACE, &to[r], &e);
        else
            gdt_pack_free(&to[r]);
    }
    free(to);
    if (st != GDT_OK) {
        part_fail(m, st, &e); /* PARTS reports it */
        m->placing = 0;
    }
    m->part_t += gdt_now() - t0;
}

static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* Another rank: the index of tile k among its tiles (increasing), or -1. */
static int64_t own_index(const mr_ctx *m, uint64_t k)
{
    const uint64_t *at =
        m->own_n > 0 ? bsearch(&k, m->own_ks, m->own_n, sizeof *m->own_ks, cmp_u64) : NULL;
    return at != NULL ? (int64_t)(at - m->own_ks) : -1;
}

void mr_parts_place(mr_ctx *m, const unsigned char *msg, size_t len)
{
    gdt_unpack u;
    double t0 = gdt_now();
    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    if (len % 16 != 0 || m->fwritten == NULL) {
        gdt_error e;
        gdt_error_clear(&e);
        mr_bad_message(0, TAG_FPLACE, &e);
        gdt_error_print(&e, stderr);
        gdt_comm_abort(m->comm, (int)e.status);
        return;
    }
    while (u.at < u.n) {
        uint64_t k = gdt_unpack_u64(&u), first = gdt_unpack_u64(&u);
        int64_t i = own_index(m, k);
        gdt_error e;
        gdt_status st;
        if (i < 0) {
            gdt_error_clear(&e);
            mr_bad_message(0, TAG_FPLACE, &e);
            gdt_error_print(&e, stderr);
            gdt_comm_abort(m->comm, (int)e.status);
            return;
        }
        if (m->fwritten[i] || m->part_st != GDT_OK || m->part_out == NULL)
            continue;
        gdt_error_clear(&e);
        st = tr_out_write_faces(m->part_out, k, first, &e);
        part_fail(m, st, &e);
        m->fwritten[i] = st == GDT_OK;
    }
    m->part_t += gdt_now() - t0;
}

/* Rank 0, a text mesh, after PARTS went out: every rank's fragment
 * lengths (TSIZES; rank 0's own from its tiles ks[0, n)), the tiles'
 * fragments laid out in tile order (TPLACE to each rank: whether to place,
 * then where each of its tiles' vertex and face bytes begin), then rank
 * 0's own fragments, the separator and where its merge faces begin.  st,
 * err: rank 0's state so far (a failure places nothing anywhere). */
static gdt_status r0_place_text(mr_ctx *m, const uint64_t *ks, uint64_t n, gdt_status st,
                                gdt_error *err)
{
    tr_run *c = m->c;
    const uint64_t nt = m->ntiles;
    /* per tile: its lengths, then where they go */
    uint64_t *tv = calloc(nt + 1, sizeof *tv), *tf = calloc(nt + 1, sizeof *tf);
    uint64_t *own = malloc((2 * n + 2) * sizeof *own);
    uint64_t header = 0, nvert = 0, vat, fat, sep;
    const char *tmp = NULL;
    int ok;

    if ((tv == NULL || tf == NULL || own == NULL) && st == GDT_OK)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK)
        st = tr_out_text_sizes(c->out, ks, n, own, own + n, err);
    for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
        tv[ks[i]] = own[i];
        tf[ks[i]] = own[n + i];
    }
    for (int r = 1; r < m->size; r++) {
        unsigned char *buf = NULL;
        size_t len = 0;
        gdt_unpack u;
        mr_wait_recv(m, r, TAG_TSIZES, &buf, &len);
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        if (mr_unpack_status(m, &u, r) == GDT_OK) {
            uint64_t cnt = gdt_unpack_u64(&u), owned = 0;
            int bad;
            for (uint64_t k = 0; k < nt; k++)
                owned += m->towner[k] == r;
            /* every tile of the rank, once each, or a place would be missing */
            bad = u.bad || cnt != owned || cnt > (u.n - u.at) / 24;
            for (uint64_t i = 0, prev = 0; !bad && i < cnt; i++) {
                uint64_t k = gdt_unpack_u64(&u), v = gdt_unpack_u64(&u), f = gdt_unpack_u64(&u);
                bad = u.bad || k >= nt || m->towner[k] != r || (i > 0 && k <= prev);
                prev = k;
                if (!bad && tv != NULL && tf != NULL)
                    tv[k] = v, tf[k] = f;
            }
            if (bad)
                mr_fail(m, r, GDT_EINTERNAL, 7952, "a TSIZES message that does not parse");
        }
        free(buf);
    }
    ok = st == GDT_OK && m->job_st == GDT_OK;
    tr_out_parts_layout(c->out, &tmp, &header, &nvert);
    /* tv, tf become the places: vertex bytes from the header on, the
     * separator, then face bytes */
    vat = header;
    for (uint64_t k = 0; ok && k < nt; k++) {
        uint64_t l = tv[k];
        tv[k] = vat;
        vat += l;
    }
    sep = vat;
    fat = sep + strlen(gdt_mesh_text_separator(gdt_mesh_format_of(c->opts->output)));
    for (uint64_t k = 0; ok && k < nt; k++) {
        uint64_t l = tf[k];
        tf[k] = fat;
        fat += l;
    }
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        gdt_error e2;
        uint64_t cnt = 0;
        memset(&p, 0, sizeof p);
        gdt_error_clear(&e2);
        gdt_pack_u64(&p, (uint64_t)ok);
        for (uint64_t k = 0; ok && k < nt; k++)
            cnt += m->towner[k] == r;
        gdt_pack_u64(&p, cnt);
        for (uint64_t k = 0; ok && k < nt; k++)
            if (m->towner[k] == r) {
                gdt_pack_u64(&p, tv[k]);
                gdt_pack_u64(&p, tf[k]);
            }
        if (mr_send_pack(m, r, TAG_TPLACE, &p, &e2) != GDT_OK) {
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)e2.status);
        }
    }
    if (ok) {
        for (uint64_t i = 0; i < n; i++) {
            own[i] = tv[ks[i]];
            own[n + i] = tf[ks[i]];
        }
        st = tr_out_place_text(c->out, ks, n, own, own + n, err);
    }
    if (ok && st == GDT_OK)
        st = tr_out_text_tail(c->out, sep, fat, err);
    free(tv);
    free(tf);
    free(own);
    if (st == GDT_OK && m->job_st != GDT_OK) {
        *err = m->job_err;
        st = m->job_st;
    }
    return st;
}

/* Rank 0: the (tile, label) pairs labels[0, 2 nlab) (by tile) of rank r's
 * tiles into p: their count, then the pairs. */
static void pack_labels(const mr_ctx *m, int r, const uint64_t *labels, size_t nlab,
                        gdt_pack *p)
{
    uint64_t cnt = 0;
    for (size_t i = 0; i < nlab; i++)
        cnt += m->towner[labels[2 * i]] == r;
    gdt_pack_u64(p, cnt);
    for (size_t i = 0; cnt > 0 && i < nlab; i++)
        if (m->towner[labels[2 * i]] == r) {
            gdt_pack_u64(p, labels[2 * i]);
            gdt_pack_u64(p, labels[2 * i + 1]);
        }
}

gdt_status mr_parts_send(mr_ctx *m, int *wait, gdt_error *err)
{
    tr_run *c = m->c;
    uint64_t n = m->ntiles;
    uint64_t *labels = NULL; /* --concavity: (tile, label) pairs dropped, by tile */
    size_t nlab = 0, caplab = 0;
    const int peel = c->trim.concavity > 0;
    gdt_status st = need_places(m, err);

    *wait = 0;
    m->placing = 0; /* from here on, PARTS places what is left */
    for (uint64_t k = 0; st == GDT_OK && c->s.ranks != NULL && k < n; k++)
        c->s.ranks[0].placed_early += m->fwritten[k];
    /* each tile's kept faces (all of them without a trim rule), past the
     * tiles placed during the tile stage */
    for (uint64_t k = m->fplaced; st == GDT_OK && k < n; k++) {
        uint64_t kept = 0;
        st = tr_out_count_faces(c->out, k, &kept, peel ? &labels : NULL, &nlab, &caplab, err);
        m->first[k + 1] = m->first[k] + kept;
    }
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        gdt_error e2;
        memset(&p, 0, sizeof p);
        gdt_error_clear(&e2);
        gdt_pack_u64(&p, (uint64_t)st);
        if (st == GDT_OK) {
            gdt_pack_u64(&p, n);
            for (uint64_t k = 0; k <= n; k++)
                gdt_pack_u64(&p, m->first[k]);
            pack_labels(m, r, labels, nlab, &p); /* rank r's drops */
        }
        if (mr_send_pack(m, r, TAG_PARTS, &p, &e2) != GDT_OK) {
            /* this rank would wait for ever: the job cannot go on */
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)e2.status);
        }
    }
    if (st == GDT_OK) {
        uint64_t *mine = malloc((n + 1) * sizeof *mine), nmine = 0;
        double t0 = gdt_now();
        *wait = m->size > 1;
        if (m->part_st != GDT_OK) { /* a write of the tile stage failed */
            *err = m->part_err;
            st = m->part_st;
        }
        if (mine == NULL && st == GDT_OK)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        for (uint64_t k = 0; mine != NULL && k < n; k++)
            if (m->towner[k] == 0)
                mine[nmine++] = k;
        for (uint64_t i = 0; st == GDT_OK && i < nmine; i++)
            if (!m->fwritten[mine[i]])
                st = tr_out_write_faces(c->out, mine[i], m->first[mine[i]], err);
        if (st == GDT_OK)
            tr_out_set_tile_faces(c->out, m->first[n]);
        /* a text mesh: the other ranks wait for their places whatever
         * happened here */
        if (m->part_text)
            st = r0_place_text(m, mine, nmine, st, err);
        free(mine);
        m->part_t += gdt_now() - t0;
    }
    if (c->s.ranks != NULL)
        c->s.ranks[0].t_write = m->part_t;
    free(labels);
    return st;
}

gdt_status mr_parts_wait(mr_ctx *m, gdt_error *err)
{
    for (int got = 1; got < m->size; got++) {
        int ready = 0, from = 0, tag = 0;
        size_t len = 0, ml = 0;
        unsigned char *buf = NULL;
        gdt_unpack u;
        gdt_status st = gdt_comm_wait(m->comm, -1, TAG_WROTE, NULL, &ready, &from, &tag, &len, err);
        if (st == GDT_OK)
            st = mr_recv(m, from, TAG_WROTE, len, &buf, err);
        if (st != GDT_OK) {
            free(buf);
            gdt_error_print(err, stderr);
            gdt_comm_abort(m->comm, (int)st);
            return st;
        }
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        {
            gdt_status rst = (gdt_status)gdt_unpack_u64(&u);
            int code = (int)gdt_unpack_u64(&u);
            double t = gdt_unpack_f64(&u);
            const unsigned char *msg = gdt_unpack_bytes(&u, &ml);
            gdt_trim_counts tc;
            uint64_t early;
            tc.faces = gdt_unpack_u64(&u);
            tc.cut = gdt_unpack_u64(&u);
            tc.peeled = gdt_unpack_u64(&u);
            tc.dropped = gdt_unpack_u64(&u);
            early = gdt_unpack_u64(&u);
            if (!u.bad && from > 0 && from < m->c->s.nranks) {
                m->c->s.ranks[from].t_write = t;
                m->c->s.ranks[from].placed_early = early;
            }
            if (!u.bad && rst == GDT_OK)
                tr_out_add_counts(m->c->out, &tc); /* the rank's tiles' faces and drops */
            if (!u.bad && rst == GDT_OK && m->part_dem && m->job_st == GDT_OK) {
                /* its tiles' cells, while the others still write */
                gdt_error e3;
                gdt_error_clear(&e3);
                if (take_windows(m, from, &e3) != GDT_OK)
                    mr_fail(m, 0, e3.status, e3.code, e3.msg);
            }
            if (u.bad) {
                char text[64];
                snprintf(text, sizeof text, "a WROTE message that does not parse");
                mr_fail(m, from, GDT_EINTERNAL, 7952, text);
            } else if (rst != GDT_OK) {
                char text[GDT_ERROR_MSG_MAX];
                snprintf(text, sizeof text, "%.*s", (int)(ml < sizeof text ? ml : sizeof text - 1),
                         (const char *)msg);
                mr_fail(m, from, rst, code, text);
            }
        }
        free(buf);
    }
    if (m->job_st != GDT_OK) {
        *err = m->job_err;
        return m->job_st;
    }
    return GDT_OK;
}

/* Another rank, a text mesh: its tiles' fragment lengths to rank 0
 * (TSIZES), then, as TPLACE says, its fragments into place.  st, err: its
 * state so far (sent as the answer when it is a failure). */
static gdt_status place_text(mr_ctx *m, const uint64_t *ks, uint64_t n, gdt_status st,
                             gdt_error *err)
{
    uint64_t *len2 = malloc((2 * n + 2) * sizeof *len2), ok, cnt;
    unsigned char *buf = NULL;
    size_t len = 0;
    gdt_pack p;
    gdt_unpack u;
    gdt_error e2;

    if (st == GDT_OK && len2 == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK)
        st = m->part_out != NULL
                 ? tr_out_text_sizes(m->part_out, ks, n, len2, len2 + n, err)
                 : gdt_error_set(err, GDT_EINTERNAL, 7830, "PARTS without a part open");
    memset(&p, 0, sizeof p);
    mr_pack_status(&p, st, err);
    gdt_pack_u64(&p, st == GDT_OK ? n : 0);
    for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
        gdt_pack_u64(&p, ks[i]);
        gdt_pack_u64(&p, len2[i]);
        gdt_pack_u64(&p, len2[n + i]);
    }
    gdt_error_clear(&e2);
    if (mr_send_pack(m, 0, TAG_TSIZES, &p, &e2) != GDT_OK) {
        gdt_error_print(&e2, stderr);
        gdt_comm_abort(m->comm, (int)e2.status);
    }
    mr_wait_recv(m, 0, TAG_TPLACE, &buf, &len);
    memset(&u, 0, sizeof u);
    u.p = buf;
    u.n = len;
    ok = gdt_unpack_u64(&u);
    cnt = gdt_unpack_u64(&u);
    if (st == GDT_OK && ok && (u.bad || cnt != n || (u.n - u.at) / 16 < n))
        st = mr_bad_message(0, TAG_TPLACE, err);
    if (st == GDT_OK && ok) {
        for (uint64_t i = 0; i < n; i++) {
            len2[i] = gdt_unpack_u64(&u);
            len2[n + i] = gdt_unpack_u64(&u);
        }
        st = tr_out_place_text(m->part_out, ks, n, len2, len2 + n, err);
    }
    free(buf);
    free(len2);
    /* not placed because another rank failed: rank 0 has the job's error */
    return st;
}

/* Writes the faces of tiles ks[0, n) as PARTS (u, after its status) asks,
 * then syncs and closes the part. */
static gdt_status write_part(mr_ctx *m, const uint64_t *ks, uint64_t n, gdt_unpack *u,
                             gdt_error *err)
{
    uint64_t ntiles = gdt_unpack_u64(u);
    uint64_t *first = NULL, *pairs = NULL, np = 0;
    gdt_status st = m->part_st;
    double t0 = gdt_now();

    if (st != GDT_OK)
        *err = m->part_err;
    else if (m->part_out == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7830, "PARTS without a part open");
    else if (u->bad || ntiles != gdt_tiler_tile_count(m->c->tiler) ||
             (u->n - u->at) / 8 < ntiles + 1)
        st = mr_bad_message(0, TAG_PARTS, err);
    else if ((first = malloc((ntiles + 1) * sizeof *first)) == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t k = 0; st == GDT_OK && k <= ntiles; k++)
        first[k] = gdt_unpack_u64(u);
    if (st == GDT_OK) {
        /* --concavity: the candidates of this rank's tiles that it drops */
        np = gdt_unpack_u64(u);
        if (u->bad || np > (u->n - u->at) / 16)
            st = mr_bad_message(0, TAG_PARTS, err);
        else if ((pairs = malloc((size_t)(2 * np + 2) * sizeof *pairs)) == NULL)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        for (uint64_t i = 0; st == GDT_OK && i < 2 * np; i++)
            pairs[i] = gdt_unpack_u64(u);
        if (st == GDT_OK)
            tr_out_set_dropped(m->part_out, pairs, (size_t)np);
    }
    for (uint64_t i = 0; m->fwritten != NULL && i < n; i++)
        m->placed_early += m->fwritten[i];
    for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
        if (m->fwritten != NULL && m->fwritten[i])
            continue; /* FPLACE placed it during the tile stage */
        st = ks[i] < ntiles ? tr_out_write_faces(m->part_out, ks[i], first[ks[i]], err)
                            : mr_bad_message(0, TAG_PARTS, err);
    }
    if (m->part_text)
        st = place_text(m, ks, n, st, err);
    if (m->part_out != NULL) {
        gdt_error e2;
        gdt_status s2;
        gdt_error_clear(&e2);
        m->part_tc = tr_out_tile_counts(m->part_out);
        s2 = tr_out_close_part(m->part_out, &e2);
        m->part_out = NULL;
        tr_dem_abort(m->part_windows); /* its windows are saved */
        m->part_windows = NULL;
        if (st == GDT_OK && s2 != GDT_OK) {
            st = s2;
            *err = e2;
        }
    }
    m->part_t += gdt_now() - t0;
    free(pairs);
    free(first);
    return st;
}

void mr_parts_answer(mr_ctx *m, const uint64_t *ks, uint64_t n, const unsigned char *msg,
                     size_t len)
{
    gdt_unpack u;
    gdt_error err, e2;
    gdt_status st;
    gdt_pack p;

    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    gdt_error_clear(&err);
    st = (gdt_status)gdt_unpack_u64(&u);
    if (u.bad) {
        st = mr_bad_message(0, TAG_PARTS, &err);
    } else if (st != GDT_OK) {
        mr_parts_drop(m); /* rank 0 failed first: no part, FINAL follows */
        return;
    } else {
        st = write_part(m, ks, n, &u, &err);
    }
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, (uint64_t)st);
    gdt_pack_u64(&p, st != GDT_OK ? (uint64_t)err.code : 0);
    gdt_pack_f64(&p, m->part_t);
    gdt_pack_bytes(&p, st != GDT_OK ? err.msg : "", st != GDT_OK ? strlen(err.msg) : 0);
    gdt_pack_u64(&p, m->part_tc.faces);
    gdt_pack_u64(&p, m->part_tc.cut);
    gdt_pack_u64(&p, m->part_tc.peeled);
    gdt_pack_u64(&p, m->part_tc.dropped);
    gdt_pack_u64(&p, m->placed_early);
    gdt_error_clear(&e2);
    if (mr_send_pack(m, 0, TAG_WROTE, &p, &e2) != GDT_OK) {
        gdt_error_print(&e2, stderr);
        gdt_comm_abort(m->comm, (int)e2.status);
    }
}

void mr_parts_drop(mr_ctx *m)
{
    tr_out_abort(m->part_out);
    m->part_out = NULL;
    tr_dem_abort(m->part_windows);
    m->part_windows = NULL;
}
