/* tile_map.c — hash map from tile indices (i, j) to a 64-bit value. */
#include "private/tiler_impl.h"

#include <stdlib.h>
#include <string.h>

static size_t slot_of(const tl_map *m, int64_t i, int64_t j)
{
    uint64_t h = (uint64_t)i * UINT64_C(0x9e3779b97f4a7c15);
    h ^= (uint64_t)j + UINT64_C(0x632be59bd9b4e019) + (h << 6) + (h >> 2);
    h ^= h >> 31;
    h *= UINT64_C(0xbf58476d1ce4e5b9);
    h ^= h >> 29;
    return (size_t)h & (m->cap - 1);
}

uint64_t *tl_map_find(const tl_map *m, int64_t i, int64_t j)
{
    if (m->cap == 0)
        return NULL;
    for (size_t s = slot_of(m, i, j);; s = (s + 1) & (m->cap - 1)) {
        tl_map_entry *e = &m->e[s];
        if (!e->used)
            return NULL;
        if (e->i == i && e->j == j)
            return &e->v;
    }
}

static gdt_status grow(tl_map *m, gdt_error *err)
{
    tl_map old = *m;
    size_t cap = old.cap != 0 ? 2 * old.cap : 64;

    if (cap > SIZE_MAX / sizeof(tl_map_entry))
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (tile table)");
    m->e = calloc(cap, sizeof *m->e);
    if (m->e == NULL) {
        *m = old;
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (tile table)");
    }
    m->cap = cap;
    m->n = 0;
    for (size_t s = 0; s < old.cap; s++) {
        if (!old.e[s].used)
            continue;
        size_t d = slot_of(m, old.e[s].i, old.e[s].j);
        while (m->e[d].used)
            d = (d + 1) & (m->cap - 1);
        m->e[d] = old.e[s];
        m->n++;
    }
    free(old.e);
    return GDT_OK;
}

gdt_status tl_map_upsert(tl_map *m, int64_t i, int64_t j, uint64_t **val, gdt_error *err)
{
    uint64_t *v = tl_map_find(m, i, j);
    size_t s;

    if (v != NULL) {
        *val = v;
        return GDT_OK;
    }
    if (2 * (m->n + 1) > m->cap) {
        gdt_status st = grow(m, err);
        if (st != GDT_OK)
            return st;
    }
    s = slot_of(m, i, j);
    while (m->e[s].used)
        s = (s + 1) & (m->cap - 1);
    m->e[s].i = i;
    m->e[s].j = j;
    m->e[s].v = 0;
    m->e[s].used = 1;
    m->n++;
    *val = &m->e[s].v;
    return GDT_OK;
}

void tl_map_free(tl_map *m)
{
    free(m->e);
    memset(m, 0, sizeof *m);
}
