/* tiled_out.c — the mesh of a tiled run, written beside the tile stage (see
 * private/tiled_out.h). */
#include "private/tiled_out.h"
#include "gdt_grow.h"
#include "gdt_ply.h"
#include "private/tiled_files.h"
#include "private/tiler_io.h"

#include "gdt_grow.h"

#include <dirent.h>
#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Invariants: ready only grows; the writer reads .tri files of tiles below
 * ready only; st/err are the writer's, read by the caller after the join;
 * quit is set once, by the caller. */
struct tr_out {
    tr_out_src src;
    gdt_mesh_writer *w; /* the writer thread's until it is joined */
    gdt_ply_writer *cw; /* the check copy (src.check_ply), or NULL; likewise */
    pthread_t tid;
    int running; /* a thread was started and not yet joined */
    pthread_mutex_t mu;
    pthread_cond_t cv;
    uint64_t ready;           /* tiles with their .tri file */
    int quit;                 /* the caller gives up: stop at the next tile */
    const gdt_trim_graph *tg; /* set once, after the merge (src.trim) */
    gdt_trim_counts tc;       /* the tiles' faces and drops so far (src.trim) */
    uint32_t *cut;            /* the current tile's trim section: cut faces */
    uint32_t *cand;           /* candidates (face, label) */
    size_t cap_cut, cap_cand;
    gdt_status st;
    gdt_error err;
    double *xyz;         /* 3 TR_CHUNK */
    gdt_point *pts;      /* TR_CHUNK */
    int32_t *tri;        /* 3 TR_CHUNK */
    unsigned char *raw;  /* 12 TR_CHUNK */
    unsigned char *rbuf; /* TL_REC TR_CHUNK: the .pts reads, one buffer for every file */
    uint8_t *drop;       /* TR_CHUNK marks: faces trimmed */
    gdt_ply_part *part;  /* written in parts (src.parts, or tr_out_open_part): the records
                          * go here, at part_v (next vertex) and part_f (next face) */
    uint64_t part_v, part_f;
    uint64_t part_header, part_nvert;
    uint64_t tile_faces; /* src.parts: the faces of every tile (tr_out_set_tile_faces) */
    /* a text mesh in parts (OBJ, LandXML): records go into the fragment
     * frag while it is open, tile k's into tiles/<tile>.vtx and .ftx of
     * tv[k] and tf[k] bytes (tn[k] faces; tmade[k] bit 0: vertices, bit 1:
     * faces made), placed through tpart; rank 0's own faces follow the
     * tiles' from byte tail_at */
    int text;
    gdt_mesh_writer *frag;
    gdt_mesh_part *tpart;
    uint64_t *tv, *tf, *tn;
    uint8_t *tmade;
    uint64_t tail_at;
    const uint64_t *dlab; /* a part without the trim graph: the (tile, label) pairs it
                           * drops, sorted (tr_out_set_dropped) */
    size_t ndlab;
    const unsigned char *tile_map; /* with a DEM: the .pts file of the tile whose faces
                                    * are copied, mapped (tile_map_len bytes), or NULL */
    size_t tile_map_len;
    size_t tile_released; /* bytes of tile_map handed back from its start */
    unsigned char *mdem;         /* with a DEM: MD_RECORD TR_CHUNK bytes of merge.dem */
    void (*on_complete)(void *); /* tr_out_on_complete: called once, or never */
    void *on_complete_ctx;
};

void tr_out_on_complete(tr_out *o, void (*fn)(void *), void *ctx)
{
    o->on_complete = fn;
    o->on_complete_ctx = ctx;
}

static int stopped(const tr_out *o)
{
    return o->src.stop != NULL && *o->src.stop != 0;
}

/* Converts m face records (3 x u32 output indices, little-endian) from
 * o->raw and appends them to the mesh (and its check copy), less those drop
 * marks (drop may be NULL: none); the faces kept stay in o->tri, *kept of
 * them. */
static gdt_status put_face_records(tr_out *o, size_t m, const uint8_t *drop, size_t *kept,
                                   gdt_error *err)
{
    size_t n = 0;
    gdt_status st;
    for (size_t f = 0; f < m; f++) {
        if (drop != NULL && drop[f])
            continue;
        for (int q = 0; q < 3; q++)
            o->tri[3 * n + q] = (int32_t)tr_get_u32(o->raw + 4 * (3 * f + q));
        n++;
    }
    *kept = n;
    if (o->frag != NULL) {
        st = gdt_mesh_write_faces(o->frag, o->tri, n, err);
    } else if (o->part != NULL) {
        st = gdt_ply_part_faces(o->part, o->part_f, o->tri, n, err);
        o->part_f += n;
    } else {
        st = gdt_mesh_write_faces(o->w, o->tri, n, err);
    }
    if (st == GDT_OK && o->cw != NULL)
        st = gdt_ply_write_faces(o->cw, o->tri, n, err);
    return st;
}

/* The trim section of tile k's .tri file at path (nf faces, section at
 * offset at): its cut faces and candidates into o->cut and o->cand,
 * checked (strictly increasing faces below nf, labels below nf); counts
 * into *tc. */
static gdt_status read_trim(tr_out *o, const char *path, uint64_t at, uint64_t nf,
                            tr_trim_counts *tc, gdt_error *err)
{
    unsigned char th[TT_HEADER];
    struct stat sb;
    FILE *f = fopen(path, "rb");
    gdt_status st = GDT_OK;
    size_t got = 0;

    if (f == NULL || fstat(fileno(f), &sb) != 0 || fseeko(f, (off_t)at, SEEK_SET) != 0 ||
        (got = fread(th, 1, TT_HEADER, f)) != TT_HEADER) {
        st = got != 0 || f == NULL
                 ? gdt_error_set(err, GDT_EIO, 4805, "%s: cannot read: %s", path, strerror(errno))
                 : gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
        goto done;
    }
    if (tr_trim_check(th, at, (uint64_t)sb.st_size, nf, tc) != 0) {
        st = gdt_error_set(err, GDT_EJOB, 6802, "%s: its trim section does not fit the file", path);
        goto done;
    }
    if (gdt_grow(&o->cut, &o->cap_cut, (size_t)tc->ncut + 1, sizeof *o->cut, 256) != 0 ||
        gdt_grow(&o->cand, &o->cap_cand, 2 * (size_t)tc->ncand + 2, sizeof *o->cand, 256) != 0) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (uint64_t i = 0; i < tc->ncut + 2 * tc->ncand; i++) {
        unsigned char b[4];
        uint32_t v;
        int bad;
        if (fread(b, 1, 4, f) != 4) {
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
            goto done;
        }
        v = tr_get_u32(b);
        if (i < tc->ncut) {
            o->cut[i] = v;
            bad = v >= nf || (i > 0 && v <= o->cut[i - 1]);
        } else {
            uint64_t j = i - tc->ncut;
            o->cand[j] = v;
            bad = v >= nf || (j % 2 == 0 && j > 0 && v <= o->cand[j - 2]);
        }
        if (bad) {
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: its trim section is damaged", path);
            goto done;
        }
    }
done:
    if (f != NULL)
        fclose(f);
    return st;
}

/* Copies nf face records from the current position of f to the mesh,
 * TR_CHUNK at a time, less the faces the trim graph drops; with a DEM the
 * kept ones are rasterised with their vertices from df (merge.dem, at its
 * first record).  path, dpath name f, df in errors. */
static gdt_status copy_face_records(tr_out *o, FILE *f, FILE *df, const char *path,
                                    const char *dpath, uint64_t nf, gdt_error *err)
{
    for (uint64_t done = 0; done < nf;) {
        size_t m = nf - done < TR_CHUNK ? (size_t)(nf - done) : TR_CHUNK, kept = 0;
        gdt_status st;
        if (fread(o->raw, 12, m, f) != m)
            return gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
        if (df != NULL && fread(o->mdem, MD_RECORD, m, df) != m)
            return gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", dpath);
        if (o->tg != NULL)
            for (size_t i = 0; i < m; i++)
                o->drop[i] = (uint8_t)gdt_trim_graph_face_dropped(o->tg, done + i);
        st = put_face_records(o, m, o->tg != NULL ? o->drop : NULL, &kept, err);
        for (size_t i = 0; st == GDT_OK && df != NULL && i < m; i++) {
            gdt_raster_vertex v[3];
            if (o->tg != NULL && o->drop[i])
                continue;
            for (int q = 0; q < 3; q++) {
                const unsigned char *r = o->mdem + MD_RECORD * i + 24 * (size_t)q;
                uint64_t zb = tr_get_u64(r + 16);
                v[q].x = (int64_t)tr_get_u64(r);
                v[q].y = (int64_t)tr_get_u64(r + 8);
                memcpy(&v[q].z, &zb, sizeof v[q].z);
            }
            st = tr_dem_faces(o->src.dem, v, 1, err);
        }
        if (st != GDT_OK)
            return st;
        done += m;
    }
    return GDT_OK;
}

/* With a DEM: tile k's .pts file mapped at o->tile_map for the rasteriser,
 * which reads the points where they lie: a copy would be a tile's worth of
 * fresh memory, which costs more to fault in than the copy itself (most
 * of the file is in the page cache since pass 2).  *path: the file's path,
 * for messages (the caller frees it). */
static gdt_status map_tile_points(tr_out *o, const gdt_tile_desc *d, char **path, gdt_error *err)
{
    gdt_status st = tr_tile_path(o->src.tiles_dir, d, "pts", path, err);
    o->tile_released = 0;
    if (st == GDT_OK)
        st = tl_map_records(*path, d->points, &o->tile_map, &o->tile_map_len, err);
    return st;
}

static void unmap_tile_points(tr_out *o)
{
    tl_unmap_records(o->tile_map, o->tile_map_len);
    o->tile_map = NULL;
    o->tile_map_len = 0;
}

/* Orders (tile, label) pairs. */
static int pair_cmp(const void *a, const void *b)
{
    const uint64_t *p = a, *q = b;
    if (p[0] != q[0])
        return p[0] < q[0] ? -1 : 1;
    return p[1] < q[1] ? -1 : p[1] > q[1];
}

/* Whether --concavity drops the candidates of label `label` of tile k: the
 * trim graph's answer, or in a part without it the pairs rank 0 sent. */
static int label_dropped(const tr_out *o, uint64_t k, uint32_t label)
{
    size_t lo = 0, hi = o->ndlab;
    if (o->tg != NULL)
        return gdt_trim_graph_tile_dropped(o->tg, k, label);
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        const uint64_t *q = o->dlab + 2 * mid;
        if (q[0] < k || (q[0] == k && q[1] < label))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < o->ndlab && o->dlab[2 * lo] == k && o->dlab[2 * lo + 1] == label;
}

/* The certified faces of tile k's .tri file, read with direct I/O (the
 * file is not needed in the page cache: the merge reads only its seam);
 * with a DEM, rasterised too. */
static gdt_status copy_faces(tr_out *o, uint64_t k, gdt_error *err)
{
    gdt_tile_desc d;
    unsigned char hdr[TR_HEADER];
    char *path = NULL;
    tr_dread r;
    size_t got = 0;
    uint64_t nf, ic = 0, ia = 0;
    size_t kept = 0;
    tr_trim_counts tc = {0, 0, 0};
    char *pts_path = NULL;
    tr_dem_tile tile = {NULL, 0, 0, 0, 0, NULL};
    gdt_status st = gdt_tiler_tile_info(o->src.tiler, k, &d, err);

    memset(&r, 0, sizeof r);
    r.fd = -1;
    if (st == GDT_OK && o->src.dem != NULL)
        st = map_tile_points(o, &d, &pts_path, err);
    if (st == GDT_OK) {
        tile.rec = o->tile_map;
        tile.n = (size_t)d.points;
        tile.x0 = d.local_x0;
        tile.y0 = d.local_y0;
        tile.extent = d.local_extent;
        tile.path = pts_path;
    }
    if (st == GDT_OK && tr_dem_windowed(o->src.dem)) {
        /* another rank's DEM: the tile's cells, for rank 0 */
        st = tr_tile_path(o->src.tiles_dir, &d, "dwin", &path, err);
        if (st == GDT_OK)
            st = tr_dem_window_begin(o->src.dem, &tile, path, err);
        free(path);
        path = NULL;
    }
    if (st == GDT_OK)
        st = tr_tile_path(o->src.tiles_dir, &d, "tri", &path, err);
    if (st == GDT_OK)
        st = tr_dread_open(&r, path, TR_DREAD_BYTES, o->src.tri_cached, err);
    if (st == GDT_OK)
        st = tr_dread_bytes(&r, hdr, TR_HEADER, &got, err);
    if (st == GDT_OK && (got != TR_HEADER || memcmp(hdr, TR_MAGIC, 8) != 0 ||
                         tr_get_u64(hdr + 8) != o->src.base[k] || tr_get_u64(hdr + 16) != d.points))
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", path);
    nf = st == GDT_OK ? tr_get_u64(hdr + 24) : 0;
    if (st == GDT_OK && o->src.trim)
        st = read_trim(o, path,
                       TR_HEADER + 12 * nf + TR_SEAM_VERTEX * tr_get_u64(hdr + 32) +
                           16 * tr_get_u64(hdr + 40),
                       nf, &tc, err);
    for (uint64_t done = 0; st == GDT_OK && done < nf;) {
        size_t m = nf - done < TR_CHUNK ? (size_t)(nf - done) : TR_CHUNK;
        st = tr_dread_bytes(&r, o->raw, 12 * m, &got, err);
        if (st == GDT_OK && got != 12 * m)
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
        if (st == GDT_OK && o->src.trim) {
            /* cut and candidates are by increasing face: two cursors */
            memset(o->drop, 0, m);
            for (; ic < tc.ncut && o->cut[ic] < done + m; ic++) {
                o->drop[o->cut[ic] - done] = 1;
                o->tc.cut++;
            }
            for (; ia < tc.ncand && o->cand[2 * ia] < done + m; ia++) {
                if (!label_dropped(o, k, o->cand[2 * ia + 1]))
                    continue;
                o->tc.peeled++;
                o->drop[o->cand[2 * ia] - done] = 1;
            }
            for (size_t i = 0; i < m; i++)
                o->tc.dropped += o->drop[i];
        }
        if (st == GDT_OK)
            st = put_face_records(o, m, o->src.trim ? o->drop : NULL, &kept, err);
        /* the DEM takes the faces the mesh keeps (o->tri holds them) */
        if (st == GDT_OK && o->src.dem != NULL) {
            /* while tiles are still coming, the cores are busy with them:
             * helper threads would only take turns with the core */
            int alone;
            pthread_mutex_lock(&o->mu);
            alone = o->ready < o->src.ntiles;
            pthread_mutex_unlock(&o->mu);
            st = tr_dem_tile_faces(o->src.dem, &tile, o->src.base[k], o->tri, kept, alone, err);
            /* the faces given before are done, and these and all to come
             * are sorted by their smallest vertex, the first face's first:
             * no face reads a point below it again, so the mapping's
             * resident pages stay near the faces being copied (for a cloud
             * in acquisition order) */
            if (st == GDT_OK && m > 0 && tr_get_u32(o->raw) >= o->src.base[k])
                tl_release_records(o->tile_map, o->tile_map_len, &o->tile_released,
                                   tr_get_u32(o->raw) - o->src.base[k]);
        }
        done += m;
    }
    if (o->src.dem != NULL) {
        /* the tile's points (o->tile_map) are the helpers' until they finish */
        gdt_error werr;
        gdt_status ws = tr_dem_tile_wait(o->src.dem, &werr);
        if (st == GDT_OK && ws != GDT_OK) {
            st = ws;
            *err = werr;
        }
        unmap_tile_points(o);
    }
    free(pts_path);
    if (st == GDT_OK)
        o->tc.faces += nf;
    tr_dread_close(&r);
    free(path);
    path = NULL;
    if (st == GDT_OK && tr_dem_windowed(o->src.dem))
        st = tr_dem_window_save(o->src.dem, err);
    return st;
}

/* The faces of the seam merge (merge.faces). */
static gdt_status copy_merge_faces(tr_out *o, const char *path, const char *dpath, uint64_t nf,
                                   gdt_error *err)
{
    unsigned char hdr[MF_HEADER];
    FILE *f = fopen(path, "rb"), *df = NULL;
    struct stat sb;
    gdt_status st = GDT_OK;

    if (f == NULL || fstat(fileno(f), &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", path, strerror(errno));
        goto fail;
    }
    if (fread(hdr, 1, MF_HEADER, f) != MF_HEADER || memcmp(hdr, MF_MAGIC, 8) != 0 ||
        tr_get_u64(hdr + 8) != nf || (uint64_t)sb.st_size != MF_HEADER + 12 * nf) {
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the merge file this run wrote", path);
        goto fail;
    }
    if (dpath != NULL) {
        df = fopen(dpath, "rb");
        if (df == NULL || fstat(fileno(df), &sb) != 0) {
            st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", dpath, strerror(errno));
            goto fail;
        }
        if (fread(hdr, 1, MF_HEADER, df) != MF_HEADER || memcmp(hdr, MD_MAGIC, 8) != 0 ||
            tr_get_u64(hdr + 8) != nf || nf > ((uint64_t)sb.st_size - MF_HEADER) / MD_RECORD ||
            (uint64_t)sb.st_size != MF_HEADER + MD_RECORD * nf) {
            st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the merge file this run wrote", dpath);
            goto fail;
        }
        if (o->mdem == NULL && (o->mdem = malloc(MD_RECORD * (size_t)TR_CHUNK)) == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
    }
    st = copy_face_records(o, f, df, path, dpath, nf, err);
fail:
    if (f != NULL)
        fclose(f);
    if (df != NULL)
        fclose(df);
    return st;
}

/* Tile k's points (by lowest input ordinal) as PLY vertices. */
static gdt_status write_vertices(tr_out *o, uint64_t k, gdt_error *err)
{
    const gdt_lattice *L = &o->src.meta.lattice;
    gdt_tile_desc d;
    tl_rfile rf;
    char *path = NULL;
    gdt_status st = gdt_tiler_tile_info(o->src.tiler, k, &d, err);

    memset(&rf, 0, sizeof rf);
    rf.fd = -1;
    if (st == GDT_OK)
        st = tr_tile_path(o->src.tiles_dir, &d, "pts", &path, err);
    if (st == GDT_OK)
        st = tl_rfile_open_buf(&rf, path, d.points, o->rbuf, TR_CHUNK, err);
    free(path);
    if (st != GDT_OK)
        return st;
    for (;;) {
        size_t m = 0;
        st = tl_rfile_read(&rf, o->pts, TR_CHUNK, &m, err);
        if (st != GDT_OK || m == 0)
            break;
        for (size_t i = 0; i < m; i++) {
            o->xyz[3 * i + 0] = L->ox + L->sx * (double)o->pts[i].x;
            o->xyz[3 * i + 1] = L->oy + L->sy * (double)o->pts[i].y;
            o->xyz[3 * i + 2] = o->pts[i].z;
        }
        if (o->frag != NULL) {
            st = gdt_mesh_write_vertices(o->frag, o->xyz, m, err);
        } else if (o->part != NULL) {
            st = gdt_ply_part_vertices(o->part, o->part_v, o->xyz, m, err);
            o->part_v += m;
        } else {
            st = gdt_mesh_write_vertices(o->w, o->xyz, m, err);
        }
        if (st == GDT_OK && o->cw != NULL)
            st = gdt_ply_write_vertices(o->cw, o->xyz, m, err);
        if (st != GDT_OK)
            break;
    }
    tl_rfile_close(&rf);
    return st;
}

/* Removes what a killed writer left beside the output: "<name>.tmp-<pid>"
 * files (gdt_mesh_out.h) whose process no longer exists. */
static void remove_stale_temps(const char *output)
{
    const char *slash = strrchr(output, '/');
    const char *base = slash != NULL ? slash + 1 : output;
    size_t dl = slash != NULL ? (size_t)(slash - output) : 0, bl = strlen(base);
    char *dir = malloc(dl + 2);
    DIR *d;
    struct dirent *e;
    if (dir == NULL)
        return;
    if (slash != NULL) {
        memcpy(dir, output, dl);
        dir[dl] = '\0';
        if (dl == 0)
            strcpy(dir, "/");
    } else {
        strcpy(dir, ".");
    }
    d = opendir(dir);
    while (d != NULL && (e = readdir(d)) != NULL) {
        const char *nm = e->d_name, *q;
        long pid;
        char *end;
        if (strncmp(nm, base, bl) != 0 || strncmp(nm + bl, ".tmp-", 5) != 0)
            continue;
        q = nm + bl + 5;
        errno = 0;
        pid = strtol(q, &end, 10);
        if (*q == '\0' || *end != '\0' || errno != 0 || pid <= 0 || (pid_t)pid == getpid())
            continue;
        if (kill((pid_t)pid, 0) != 0 && errno == ESRCH)
            unlinkat(dirfd(d), nm, 0);
    }
    if (d != NULL)
        closedir(d);
    free(dir);
}

/* Waits until tile k has its .tri file; 0 when the caller gives up. */
static int wait_ready(tr_out *o, uint64_t k)
{
    int go;
    pthread_mutex_lock(&o->mu);
    while (o->ready <= k && !o->quit)
        pthread_cond_wait(&o->cv, &o->mu);
    go = !o->quit;
    pthread_mutex_unlock(&o->mu);
    return go;
}

/* Waits until the trim graph is set (tr_out_set_trim); 0 when the caller
 * gives up. */
static int wait_trim(tr_out *o)
{
    int go;
    pthread_mutex_lock(&o->mu);
    while (o->tg == NULL && !o->quit)
        pthread_cond_wait(&o->cv, &o->mu);
    go = !o->quit;
    pthread_mutex_unlock(&o->mu);
    return go;
}

/* 1 when the caller gave up (tr_out_abort). */
static int quitting(tr_out *o)
{
    int q;
    pthread_mutex_lock(&o->mu);
    q = o->quit;
    pthread_mutex_unlock(&o->mu);
    return q;
}

/* The PLY meta of the check copy. */
static gdt_ply_meta check_meta(const gdt_mesh_meta *m)
{
    gdt_ply_meta p;
    memset(&p, 0, sizeof p);
    p.lattice = m->lattice;
    p.epsg = m->epsg;
    p.crs_wkt = m->crs_wkt;
    p.comments = m->comments;
    p.ncomments = m->ncomments;
    return p;
}

/* The writer: the mesh's header and vertices, then each tile's faces. */
static gdt_status write_tiles(tr_out *o, gdt_error *err)
{
    uint64_t n = o->src.ntiles;
    gdt_status st =
        gdt_mesh_create(&o->w, o->src.output, gdt_mesh_format_of(o->src.output), &o->src.meta, err);
    if (st == GDT_OK && o->src.check_ply != NULL) {
        gdt_ply_meta pm = check_meta(&o->src.meta);
        st = gdt_ply_create(&o->cw, o->src.check_ply, &pm, err);
    }
    for (uint64_t k = 0; st == GDT_OK && k < n; k++)
        st = stopped(o) || quitting(o) ? tr_interrupted(o->src.job, "the output", err)
                                       : write_vertices(o, k, err);
    if (st == GDT_OK && o->src.concavity && (!wait_trim(o) || stopped(o)))
        st = tr_interrupted(o->src.job, "the output", err);
    for (uint64_t k = 0; st == GDT_OK && k < n; k++) {
        if (!wait_ready(o, k) || stopped(o))
            st = tr_interrupted(o->src.job, "the output", err);
        else
            st = copy_faces(o, k, err);
    }
    return st;
}

static void *out_main(void *arg)
{
    tr_out *o = arg;
    gdt_error e;
    gdt_status st;
    gdt_error_clear(&e);
    st = write_tiles(o, &e);
    o->st = st;
    o->err = e;
    return NULL;
}

static void out_free(tr_out *o)
{
    gdt_ply_part_abort(o->part);
    gdt_mesh_abort(o->frag);
    gdt_mesh_part_abort(o->tpart);
    free(o->tv);
    free(o->tf);
    free(o->tn);
    free(o->tmade);
    gdt_mesh_abort(o->w);
    gdt_ply_abort(o->cw);
    pthread_cond_destroy(&o->cv);
    pthread_mutex_destroy(&o->mu);
    free(o->xyz);
    free(o->pts);
    free(o->tri);
    free(o->raw);
    free(o->rbuf);
    free(o->drop);
    free(o->cut);
    free(o->cand);
    unmap_tile_points(o);
    free(o->mdem);
    free(o);
}

/* A writer's state without a thread or a file: src and the buffers. */
static gdt_status out_alloc(tr_out **out, const tr_out_src *src, gdt_error *err)
{
    tr_out *o = calloc(1, sizeof *o);
    *out = NULL;
    if (o == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    o->src = *src;
    pthread_mutex_init(&o->mu, NULL);
    pthread_cond_init(&o->cv, NULL);
    o->xyz = malloc(3 * TR_CHUNK * sizeof *o->xyz);
    o->pts = malloc(TR_CHUNK * sizeof *o->pts);
    o->tri = malloc(3 * TR_CHUNK * sizeof *o->tri);
    o->raw = malloc(12 * TR_CHUNK);
    o->rbuf = malloc((size_t)TL_REC * TR_CHUNK);
    o->drop = malloc(TR_CHUNK);
    if (o->xyz == NULL || o->pts == NULL || o->tri == NULL || o->raw == NULL || o->rbuf == NULL ||
        o->drop == NULL) {
        out_free(o);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    *out = o;
    return GDT_OK;
}

/* The per-tile fragment records of a text mesh in parts. */
static gdt_status text_alloc(tr_out *o, gdt_error *err)
{
    size_t n = (size_t)o->src.ntiles + 1;
    o->text = 1;
    o->tv = calloc(n, sizeof *o->tv);
    o->tf = calloc(n, sizeof *o->tf);
    o->tn = calloc(n, sizeof *o->tn);
    o->tmade = calloc(n, 1);
    if (o->tv == NULL || o->tf == NULL || o->tn == NULL || o->tmade == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}

gdt_status tr_out_start(tr_out **out, const tr_out_src *src, gdt_error *err)
{
    tr_out *o;
    gdt_status st = out_alloc(&o, src, err);
    *out = NULL;
    if (st != GDT_OK)
        return st;
    remove_stale_temps(src->output);
    {
        char *prj = gdt_mesh_prj_path(src->output, gdt_mesh_format_of(src->output));
        if (prj != NULL)
            remove_stale_temps(prj);
        free(prj);
    }
    if (src->check_ply != NULL)
        remove_stale_temps(src->check_ply);
    if (src->parts && gdt_mesh_format_of(src->output) != GDT_MESH_PLY) {
        /* a text mesh: the header now; the records in fragments, placed
         * once their lengths are known; rank 0's own faces last */
        o->part_nvert = src->base[src->ntiles];
        st = src->check_ply == NULL
                 ? gdt_mesh_create(&o->w, src->output, gdt_mesh_format_of(src->output), &src->meta,
                                   err)
                 : gdt_error_set(err, GDT_EINTERNAL, 7830,
                                 "the mesh written in parts must be without a check copy");
        if (st == GDT_OK)
            st = gdt_mesh_begin_text_parts(o->w, &o->part_header, err);
        if (st == GDT_OK)
            st = text_alloc(o, err);
        if (st == GDT_OK)
            st = gdt_mesh_part_open(&o->tpart, gdt_mesh_temp_path(o->w), err);
        if (st != GDT_OK) {
            out_free(o);
            return st;
        }
        *out = o;
        return GDT_OK;
    }
    if (src->parts) {
        /* the header now; every record through parts (this one for rank 0) */
        gdt_ply_writer *pw;
        o->part_nvert = src->base[src->ntiles];
        st = src->check_ply == NULL
                 ? gdt_mesh_create(&o->w, src->output, GDT_MESH_PLY, &src->meta, err)
                 : gdt_error_set(err, GDT_EINTERNAL, 7830,
                                 "the mesh written in parts must be without a check copy");
        pw = st == GDT_OK ? gdt_mesh_ply_writer(o->w) : NULL;
        if (st == GDT_OK)
            st = gdt_ply_begin_parts(pw, o->part_nvert, &o->part_header, err);
        if (st == GDT_OK)
            st = gdt_ply_part_open(&o->part, gdt_ply_temp_path(pw), o->part_header, o->part_nvert,
                                   err);
        if (st != GDT_OK) {
            out_free(o);
            return st;
        }
        *out = o;
        return GDT_OK;
    }
    o->running = pthread_create(&o->tid, NULL, out_main, o) == 0;
    *out = o;
    return GDT_OK;
}

void tr_out_parts_layout(const tr_out *o, const char **tmp_path, uint64_t *header, uint64_t *nvert)
{
    *tmp_path = gdt_mesh_temp_path(o->w);
    *header = o->part_header;
    *nvert = o->part_nvert;
}

gdt_status tr_out_open_part(tr_out **out, const tr_out_src *src, const char *tmp_path,
                            uint64_t header, uint64_t nvert, gdt_error *err)
{
    tr_out *o;
    gdt_status st = out_alloc(&o, src, err);
    *out = NULL;
    if (st != GDT_OK)
        return st;
    o->part_header = header;
    o->part_nvert = nvert;
    if (gdt_mesh_format_of(src->output) != GDT_MESH_PLY) {
        st = text_alloc(o, err);
        if (st == GDT_OK)
            st = gdt_mesh_part_open(&o->tpart, tmp_path, err);
    } else {
        st = gdt_ply_part_open(&o->part, tmp_path, header, nvert, err);
    }
    if (st != GDT_OK) {
        out_free(o);
        return st;
    }
    *out = o;
    return GDT_OK;
}

gdt_status tr_out_count_faces(tr_out *o, uint64_t k, uint64_t *kept, uint64_t **labels,
                              size_t *nlabels, size_t *cap, gdt_error *err)
{
    gdt_tile_desc d;
    unsigned char hdr[TR_HEADER];
    char *path = NULL;
    FILE *f = NULL;
    uint64_t nf = 0;
    size_t first = nlabels != NULL ? *nlabels : 0;
    gdt_status st = gdt_tiler_tile_info(o->src.tiler, k, &d, err);
    if (st == GDT_OK)
        st = tr_tile_path(o->src.tiles_dir, &d, "tri", &path, err);
    if (st == GDT_OK && (f = fopen(path, "rb")) == NULL)
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", path, strerror(errno));
    if (st == GDT_OK &&
        (fread(hdr, 1, TR_HEADER, f) != TR_HEADER || memcmp(hdr, TR_MAGIC, 8) != 0 ||
         tr_get_u64(hdr + 8) != o->src.base[k] || tr_get_u64(hdr + 16) != d.points))
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", path);
    if (f != NULL)
        fclose(f);
    if (st == GDT_OK)
        nf = *kept = tr_get_u64(hdr + 24);
    if (st == GDT_OK && o->src.trim) {
        tr_trim_counts tc = {0, 0, 0};
        uint64_t dropped, ic = 0;
        st = read_trim(o, path,
                       TR_HEADER + 12 * nf + TR_SEAM_VERTEX * tr_get_u64(hdr + 32) +
                           16 * tr_get_u64(hdr + 40),
                       nf, &tc, err);
        /* cut faces, and the peeled candidates that are not cut too (both
         * lists by increasing face) */
        dropped = tc.ncut;
        for (uint64_t ia = 0; st == GDT_OK && ia < tc.ncand; ia++) {
            uint32_t face = o->cand[2 * ia], label = o->cand[2 * ia + 1];
            if (!label_dropped(o, k, label))
                continue;
            while (ic < tc.ncut && o->cut[ic] < face)
                ic++;
            dropped += !(ic < tc.ncut && o->cut[ic] == face);
            if (labels != NULL) {
                if (gdt_grow(labels, cap, 2 * (*nlabels + 1), sizeof **labels, 256) != 0) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                    break;
                }
                (*labels)[2 * *nlabels] = k;
                (*labels)[2 * *nlabels + 1] = label;
                (*nlabels)++;
            }
        }
        if (st == GDT_OK)
            *kept = nf - dropped;
        if (st == GDT_OK && labels != NULL && *nlabels > first) {
            /* the tile's labels (its pairs share the tile), sorted and each
             * once */
            uint64_t *q = *labels + 2 * first;
            size_t n = *nlabels - first, w = 0;
            qsort(q, n, 2 * sizeof *q, pair_cmp);
            for (size_t a = 0; a < n; a++)
                if (w == 0 || q[2 * a + 1] != q[2 * w - 1]) {
                    q[2 * w] = k;
                    q[2 * w + 1] = q[2 * a + 1];
                    w++;
                }
            *nlabels = first + w;
        }
    }
    free(path);
    return st;
}

void tr_out_set_dropped(tr_out *o, const uint64_t *pairs, size_t n)
{
    o->dlab = pairs;
    o->ndlab = n;
}

gdt_trim_counts tr_out_tile_counts(const tr_out *o)
{
    return o->tc;
}

/* The fragment of tile k's vertices (faces == 0) or faces: tiles/<tile>.vtx
 * or .ftx, into *path (the caller frees it). */
static gdt_status fragment_path(const tr_out *o, uint64_t k, int faces, char **path, gdt_error *err)
{
    gdt_tile_desc d;
    gdt_status st = gdt_tiler_tile_info(o->src.tiler, k, &d, err);
    *path = NULL;
    if (st == GDT_OK)
        st = tr_tile_path(o->src.tiles_dir, &d, faces ? "ftx" : "vtx", path, err);
    return st;
}

/* Tile k's vertices (faces == 0) or kept faces into their fragment. */
static gdt_status make_fragment(tr_out *o, uint64_t k, int faces, gdt_error *err)
{
    char *path = NULL;
    uint64_t bytes = 0;
    gdt_status st = fragment_path(o, k, faces, &path, err);
    if (st == GDT_OK)
        st = gdt_mesh_fragment_create(&o->frag, path, gdt_mesh_format_of(o->src.output),
                                      faces ? o->part_nvert : o->src.base[k], faces, err);
    if (st == GDT_OK)
        st = faces ? copy_faces(o, k, err) : write_vertices(o, k, err);
    if (st == GDT_OK && faces)
        o->tn[k] = gdt_mesh_face_count(o->frag);
    if (o->frag != NULL) {
        gdt_mesh_writer *fw = o->frag;
        o->frag = NULL;
        if (st == GDT_OK)
            st = gdt_mesh_fragment_close(fw, &bytes, err);
        else
            gdt_mesh_abort(fw);
    }
    if (st == GDT_OK) {
        if (faces)
            o->tf[k] = bytes;
        else
            o->tv[k] = bytes;
        o->tmade[k] |= (uint8_t)(faces ? 2 : 1);
    }
    free(path);
    return st;
}

gdt_status tr_out_write_vertices(tr_out *o, uint64_t k, gdt_error *err)
{
    if ((o->part == NULL && !o->text) || k >= o->src.ntiles)
        return gdt_error_set(err, GDT_EINTERNAL, 7830, "tile %" PRIu64 " written outside parts", k);
    if (o->text)
        return make_fragment(o, k, 0, err);
    o->part_v = o->src.base[k];
    return write_vertices(o, k, err);
}

gdt_status tr_out_write_faces(tr_out *o, uint64_t k, uint64_t first_face, gdt_error *err)
{
    if ((o->part == NULL && !o->text) || k >= o->src.ntiles)
        return gdt_error_set(err, GDT_EINTERNAL, 7830, "tile %" PRIu64 " written outside parts", k);
    if (o->text) /* made once: during the tile stage, or after the merge's peel */
        return (o->tmade[k] & 2) != 0 ? GDT_OK : make_fragment(o, k, 1, err);
    o->part_f = first_face;
    return copy_faces(o, k, err);
}

int tr_out_text(const tr_out *o)
{
    return o != NULL && o->text;
}

gdt_status tr_out_text_sizes(const tr_out *o, const uint64_t *ks, uint64_t n, uint64_t *vbytes,
                             uint64_t *fbytes, gdt_error *err)
{
    for (uint64_t i = 0; i < n; i++) {
        uint64_t k = ks[i];
        if (k >= o->src.ntiles || o->tmade[k] != 3)
            return gdt_error_set(err, GDT_EINTERNAL, 7830,
                                 "tile %" PRIu64 " of a text mesh has no fragments", k);
        vbytes[i] = o->tv[k];
        fbytes[i] = o->tf[k];
    }
    return GDT_OK;
}

gdt_status tr_out_place_text(tr_out *o, const uint64_t *ks, uint64_t n, const uint64_t *vat,
                             const uint64_t *fat, gdt_error *err)
{
    gdt_status st = GDT_OK;
    for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
        uint64_t k = ks[i];
        for (int faces = 0; st == GDT_OK && faces < 2; faces++) {
            char *path = NULL;
            uint64_t len = faces ? o->tf[k] : o->tv[k];
            st = fragment_path(o, k, faces, &path, err);
            if (st == GDT_OK)
                st = gdt_mesh_part_copy(o->tpart, path, len, faces ? fat[i] : vat[i], err);
            if (st == GDT_OK)
                unlink(path); /* placed: its bytes are in the mesh */
            free(path);
        }
    }
    return st;
}

gdt_status tr_out_text_tail(tr_out *o, uint64_t sep_at, uint64_t tail_at, gdt_error *err)
{
    const char *sep = gdt_mesh_text_separator(gdt_mesh_format_of(o->src.output));
    gdt_status st = gdt_mesh_part_write(o->tpart, sep, strlen(sep), sep_at, err);
    o->tail_at = tail_at;
    return st;
}

gdt_status tr_out_close_part(tr_out *o, gdt_error *err)
{
    gdt_status st = o->text ? gdt_mesh_part_close(o->tpart, err) : gdt_ply_part_close(o->part, err);
    o->part = NULL;
    o->tpart = NULL;
    out_free(o);
    return st;
}

void tr_out_set_tile_faces(tr_out *o, uint64_t n)
{
    o->tile_faces = n;
}

void tr_out_add_counts(tr_out *o, const gdt_trim_counts *tc)
{
    o->tc.faces += tc->faces;
    o->tc.cut += tc->cut;
    o->tc.peeled += tc->peeled;
    o->tc.dropped += tc->dropped;
}

void tr_out_ready(tr_out *o, uint64_t n)
{
    if (o->src.parts)
        return; /* no thread waits */
    pthread_mutex_lock(&o->mu);
    if (n > o->ready) {
        o->ready = n;
        pthread_cond_signal(&o->cv);
    }
    pthread_mutex_unlock(&o->mu);
}

void tr_out_set_trim(tr_out *o, const gdt_trim_graph *g)
{
    pthread_mutex_lock(&o->mu);
    o->tg = g;
    pthread_cond_signal(&o->cv);
    pthread_mutex_unlock(&o->mu);
}

/* Joins the writer (asking it to stop first if quit). */
static void out_join(tr_out *o, int quit)
{
    if (!o->running)
        return;
    if (quit) {
        pthread_mutex_lock(&o->mu);
        o->quit = 1;
        pthread_cond_signal(&o->cv);
        pthread_mutex_unlock(&o->mu);
    }
    pthread_join(o->tid, NULL);
    o->running = 0;
}

/* The counts of a mesh written in parts: the merge's (m) and, trimmed,
 * every tile's (tr_out_add_counts). */
static void parts_counts(const tr_out *o, const gdt_trim_counts *m, uint64_t merge_faces,
                         gdt_trim_counts *tc)
{
    if (o->src.trim) {
        *tc = o->tc;
        tc->faces += m->faces;
        tc->cut += m->cut;
        tc->peeled += m->peeled;
        tc->dropped += m->dropped;
    } else {
        memset(tc, 0, sizeof *tc);
        tc->faces = o->tile_faces + merge_faces;
    }
}

gdt_status tr_out_finish(tr_out *o, const char *merge_path, const char *merge_dem,
                         uint64_t merge_faces, gdt_trim_counts *tc, gdt_error *err)
{
    gdt_status st;
    if (o->w != NULL && o->text) { /* a text mesh in parts: the merge's faces last */
        gdt_trim_counts m;
        memset(&m, 0, sizeof m);
        if (o->tg != NULL)
            m = gdt_trim_graph_merge_counts(o->tg);
        st = gdt_mesh_part_close(o->tpart, err); /* the separator rank 0 wrote */
        o->tpart = NULL;
        if (st == GDT_OK)
            st = gdt_mesh_resume_text(o->w, o->tail_at, o->part_nvert, o->tile_faces, err);
        if (st == GDT_OK)
            st = stopped(o) ? tr_interrupted(o->src.job, "the output", err)
                            : copy_merge_faces(o, merge_path, merge_dem, merge_faces, err);
        if (st == GDT_OK && o->on_complete != NULL)
            o->on_complete(o->on_complete_ctx);
        if (st == GDT_OK) {
            st = gdt_mesh_finish(o->w, err);
            o->w = NULL;
        }
        parts_counts(o, &m, merge_faces, tc);
        out_free(o);
        return st;
    }
    if (o->w != NULL && o->part != NULL) { /* written in parts: the merge's faces last */
        gdt_trim_counts m;
        memset(&m, 0, sizeof m);
        if (o->tg != NULL)
            m = gdt_trim_graph_merge_counts(o->tg);
        o->part_f = o->tile_faces;
        st = stopped(o) ? tr_interrupted(o->src.job, "the output", err)
                        : copy_merge_faces(o, merge_path, merge_dem, merge_faces, err);
        if (st == GDT_OK && o->on_complete != NULL)
            o->on_complete(o->on_complete_ctx);
        if (st == GDT_OK)
            st = gdt_ply_part_close(o->part, err);
        o->part = NULL;
        if (st == GDT_OK)
            st = gdt_mesh_finish_parts(o->w, o->tile_faces + merge_faces - m.dropped, err);
        o->w = NULL;
        parts_counts(o, &m, merge_faces, tc);
        out_free(o);
        return st;
    }
    tr_out_ready(o, o->src.ntiles);
    if (o->running) {
        out_join(o, 0);
        st = o->st;
        if (st != GDT_OK)
            *err = o->err;
    } else {
        st = write_tiles(o, err); /* no thread could be started */
    }
    if (st == GDT_OK)
        st = stopped(o) ? tr_interrupted(o->src.job, "the output", err)
                        : copy_merge_faces(o, merge_path, merge_dem, merge_faces, err);
    if (st == GDT_OK && o->on_complete != NULL)
        o->on_complete(o->on_complete_ctx);
    if (st == GDT_OK && o->cw != NULL) {
        st = gdt_ply_finish(o->cw, err);
        o->cw = NULL;
    }
    if (st == GDT_OK) {
        st = gdt_mesh_finish(o->w, err);
        o->w = NULL;
    }
    *tc = o->tc;
    if (o->tg != NULL) {
        gdt_trim_counts m = gdt_trim_graph_merge_counts(o->tg);
        tc->faces += m.faces;
        tc->cut += m.cut;
        tc->peeled += m.peeled;
        tc->dropped += m.dropped;
    }
    out_free(o);
    return st;
}

void tr_out_abort(tr_out *o)
{
    if (o == NULL)
        return;
    out_join(o, 1);
    out_free(o);
}
