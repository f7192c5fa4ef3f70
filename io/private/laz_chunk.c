/* laz_chunk.c — the chunk decoder of laz_chunk.h: dispatches to the item
 * decoders of the VLR's compressor. */
#include "laz_chunk.h"

#include <stdlib.h>

#include "laz10.h"
#include "laz14.h"

struct gdt_laz_chunk {
    const gdt_laz_vlr *vlr;
    unsigned record_length, need;
    gdt_laz10 *pointwise; /* compressor 2 */
    gdt_laz14 *layered;   /* compressor 3 */
};

gdt_status gdt_laz_chunk_new(gdt_laz_chunk **out, const gdt_laz_vlr *vlr,
                             unsigned record_length, unsigned need, gdt_error *err)
{
    gdt_laz_chunk *c;
    gdt_status st;

    *out = NULL;
    if (vlr->compressor != GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED &&
        vlr->compressor != GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED)
        return gdt_error_set(err, GDT_EINPUT, 3902, "LAZ compressor %u has no chunk decoder",
                             (unsigned)vlr->compressor);
    c = calloc(1, sizeof *c);
    if (!c)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    c->vlr = vlr;
    c->record_length = record_length;
    c->need = need;
    if (vlr->compressor == GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED)
        st = gdt_laz14_new(&c->layered, vlr, record_length, need, err);
    else
        st = gdt_laz10_new(&c->pointwise, vlr, record_length, err);
    if (st != GDT_OK) {
        free(c);
        return st;
    }
    *out = c;
    return GDT_OK;
}

void gdt_laz_chunk_free(gdt_laz_chunk *c)
{
    if (!c)
        return;
    gdt_laz10_free(c->pointwise);
    gdt_laz14_free(c->layered);
    free(c);
}

gdt_status gdt_laz_chunk_start(gdt_laz_chunk *c, const unsigned char *data, size_t avail,
                               uint64_t npoints, const char *path, uint64_t chunk_index,
                               gdt_error *err)
{
    if (c->layered)
        return gdt_laz14_start(c->layered, data, avail, npoints, path, chunk_index, err);
    return gdt_laz10_start(c->pointwise, data, avail, npoints, path, chunk_index, err);
}

gdt_status gdt_laz_chunk_read(gdt_laz_chunk *c, unsigned char *records, size_t n,
                              gdt_error *err)
{
    if (c->layered)
        return gdt_laz14_read(c->layered, records, n, err);
    return gdt_laz10_read(c->pointwise, records, n, err);
}

size_t gdt_laz_chunk_used(const gdt_laz_chunk *c)
{
    if (c->layered)
        return gdt_laz14_used(c->layered);
    return gdt_laz10_used(c->pointwise);
}
