/* run_lanes.c — several devices in one tile stage (see private/stages.h,
 * tr_lanes_*).
 *
 * The first core runs on the tile stage's own thread as with one device;
 * every further core ("lane") has a thread that triangulates tiles ahead of
 * the stage: the lowest tile of the set that needs the core (no file of it
 * in the job) and that nobody has taken yet.  The stage takes its tiles in
 * order: a tile a lane has taken is waited for, any other is triangulated
 * on the stage's thread.  The post stage is unchanged (one tile at a time,
 * in order), so the files, the journal and the output are those of one
 * device: the core's result does not depend on the device.
 *
 * Slots: 2 + 2 * lanes.  The stage holds at most two (the tile in its post
 * stage and the current one); lanes hold at most the others, so the stage
 * always finds a free slot for a tile it triangulates itself.
 *
 * Invariants (under mu): state[i] is FREE, TAKEN (a lane works on it), DONE
 * (slot_of[i] holds it) or FAILED (the lowest failed tile is fail_i, its
 * error fail_st and fail_err); busy[s] is set from a
 * slot's claim until its post stage was joined (tr_lanes_posted);
 * lane_held counts the slots lanes claimed that the stage has not taken. */
#define _GNU_SOURCE 1 /* pthread_setname_np */
#include "private/stages.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "private/run_stats.h"

enum { LN_FREE = 0, LN_TAKEN, LN_DONE, LN_FAILED };

typedef struct tr_lane {
    struct tr_lanes *p;
    gdt_core *core;
    gdt_point_buf halo;
    tr_core_counts counts;
    pthread_t tid;
    int started;
} tr_lane;

struct tr_lanes {
    tr_run *c;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    uint64_t n;              /* tiles in the set */
    uint64_t *k;             /* the set's tile of each i */
    unsigned char *todo;     /* i needs the core and a lane may take it */
    unsigned char *state;    /* LN_* of each i */
    int *slot_of;            /* the slot of i once DONE */
    uint64_t scan;           /* no FREE todo i below this */
    int stop;
    uint64_t fail_i;
    gdt_status fail_st;
    gdt_error fail_err;
    int nslots, lane_held;
    tr_slot *slots;
    unsigned char *busy;
    int nlanes;
    tr_lane *lanes;
};

/* A free slot (mu held); -1 when none. */
static int free_slot(tr_lanes *p)
{
    for (int s = 0; s < p->nslots; s++)
        if (!p->busy[s])
            return s;
    return -1;
}

static void *lane_main(void *arg)
{
    tr_lane *l = arg;
    tr_lanes *p = l->p;

    pthread_mutex_lock(&p->mu);
    for (;;) {
        uint64_t i = p->scan;
        int s = -1;
        while (i < p->n && !(p->todo[i] && p->state[i] == LN_FREE))
            i++;
        p->scan = i;
        if (p->stop || i >= p->n)
            break; /* nothing left for a lane */
        if (p->lane_held < p->nslots - 2)
            s = free_slot(p);
        if (s < 0) {
            pthread_cond_wait(&p->cv, &p->mu);
            continue;
        }
        p->state[i] = LN_TAKEN;
        p->busy[s] = 1;
        p->lane_held++;
        pthread_mutex_unlock(&p->mu);
        {
            gdt_error e;
            gdt_status st;
            gdt_error_clear(&e);
            st = tr_core_tile(p->c, l->core, &l->halo, &l->counts, p->k[i], &p->slots[s], &e);
            pthread_mutex_lock(&p->mu);
            if (st == GDT_OK) {
                p->state[i] = LN_DONE;
                p->slot_of[i] = s;
            } else {
                /* the stage reports it when it reaches tile i; nothing
                 * more is started */
                p->state[i] = LN_FAILED;
                p->slot_of[i] = -1;
                p->busy[s] = 0;
                p->lane_held--;
                if (p->fail_st == GDT_OK || i < p->fail_i) {
                    p->fail_i = i;
                    p->fail_st = st;
                    p->fail_err = e;
                }
                p->stop = 1;
            }
            pthread_cond_broadcast(&p->cv);
        }
    }
    pthread_mutex_unlock(&p->mu);
    return NULL;
}

/* The pool's arrays and the pool (not its slots' contents). */
static void lanes_free(tr_lanes *p)
{
    free(p->k);
    free(p->todo);
    free(p->state);
    free(p->slot_of);
    free(p->slots);
    free(p->busy);
    free(p->lanes);
    free(p);
}

gdt_status tr_lanes_start(tr_run *c, const tr_tile_set *set, uint64_t n, gdt_error *err)
{
    tr_lanes *p;
    size_t nmore = c->cstart.nmore;
    gdt_status st = GDT_OK;

    c->lanes = NULL;
    if (nmore == 0 || n < 2)
        return GDT_OK;
    p = calloc(1, sizeof *p);
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    p->c = c;
    p->n = n;
    p->nlanes = (int)nmore;
    p->nslots = 2 + 2 * p->nlanes;
    p->k = calloc(n, sizeof *p->k);
    p->todo = calloc(n, 1);
    p->state = calloc(n, 1);
    p->slot_of = calloc(n, sizeof *p->slot_of);
    p->slots = calloc((size_t)p->nslots, sizeof *p->slots);
    p->busy = calloc((size_t)p->nslots, 1);
    p->lanes = calloc((size_t)p->nlanes, sizeof *p->lanes);
    if (p->k == NULL || p->todo == NULL || p->state == NULL || p->slot_of == NULL ||
        p->slots == NULL || p->busy == NULL || p->lanes == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (int s = 0; s < p->nslots; s++)
        gdt_mesh_init(&p->slots[s].mesh);
    /* which tiles need the core: those the job holds no file of (a tile
     * whose file fails its check is triangulated by the stage itself) */
    for (uint64_t i = 0; i < n && st == GDT_OK; i++) {
        int found = 0;
        uint64_t size = 0, sum = 0;
        p->k[i] = set->k != NULL ? set->k[i] : i;
        if (set->rec != NULL)
            found = set->rec[i].found;
        else
            st = gdt_job_get_tile(c->jobdb, p->k[i], &found, &size, &sum, err);
        p->todo[i] = !found;
    }
    if (st != GDT_OK)
        goto fail;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->cv, NULL);
    c->lanes = p;
    for (int j = 0; j < p->nlanes; j++) {
        tr_lane *l = &p->lanes[j];
        l->p = p;
        l->core = c->cstart.more[j];
        l->started = pthread_create(&l->tid, NULL, lane_main, l) == 0;
        if (l->started) /* for debuggers, profilers and the tests' fault shims */
            pthread_setname_np(l->tid, "gdt-lane");
    }
    return GDT_OK;
fail:
    lanes_free(p);
    return st;
}

gdt_status tr_lanes_take(tr_run *c, uint64_t i, tr_slot **sl, tr_core_counts *counts,
                         gdt_error *err)
{
    tr_lanes *p = c->lanes;
    int s;
    gdt_status st;

    pthread_mutex_lock(&p->mu);
    if (p->state[i] == LN_FREE) {
        /* the stage's own core: a free slot exists (see the header) */
        s = free_slot(p);
        if (s < 0) {
            pthread_mutex_unlock(&p->mu);
            return gdt_error_set(err, GDT_EINTERNAL, 7831,
                                 "the tile stage found no free slot for tile %d",
                                 (int)p->k[i]);
        }
        p->state[i] = LN_TAKEN;
        p->busy[s] = 1;
        pthread_mutex_unlock(&p->mu);
        st = tr_core_tile(c, c->core, &c->halo, counts, p->k[i], &p->slots[s], err);
        pthread_mutex_lock(&p->mu);
        p->state[i] = st == GDT_OK ? LN_DONE : LN_FAILED;
        if (st != GDT_OK) {
            p->busy[s] = 0;
            p->stop = 1;
            pthread_cond_broadcast(&p->cv);
            pthread_mutex_unlock(&p->mu);
            return st;
        }
        pthread_mutex_unlock(&p->mu);
        *sl = &p->slots[s];
        return GDT_OK;
    }
    while (p->state[i] == LN_TAKEN)
        pthread_cond_wait(&p->cv, &p->mu);
    if (p->state[i] == LN_FAILED) {
        /* the stage takes tiles in order: the first failure it meets is the
         * lowest one */
        st = p->fail_st;
        *err = p->fail_err;
        pthread_mutex_unlock(&p->mu);
        return st;
    }
    s = p->slot_of[i];
    p->lane_held--;
    pthread_mutex_unlock(&p->mu);
    *sl = &p->slots[s];
    return GDT_OK;
}

void tr_lanes_posted(tr_run *c, tr_slot *sl)
{
    tr_lanes *p = c->lanes;
    if (p == NULL || sl == NULL)
        return;
    pthread_mutex_lock(&p->mu);
    p->busy[sl - p->slots] = 0;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
}

void tr_lanes_stop(tr_run *c)
{
    tr_lanes *p = c->lanes;
    if (p == NULL)
        return;
    pthread_mutex_lock(&p->mu);
    p->stop = 1;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
    for (int j = 0; j < p->nlanes; j++) {
        tr_lane *l = &p->lanes[j];
        if (l->started)
            pthread_join(l->tid, NULL);
        tr_core_counts_add(c, &l->counts);
        gdt_point_buf_free(&l->halo);
    }
    for (int s = 0; s < p->nslots; s++) {
        gdt_mesh_free(&p->slots[s].mesh);
        free(p->slots[s].lh);
        free(p->slots[s].z);
    }
    pthread_mutex_destroy(&p->mu);
    pthread_cond_destroy(&p->cv);
    lanes_free(p);
    c->lanes = NULL;
}
