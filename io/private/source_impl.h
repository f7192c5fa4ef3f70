/* Internal contract between gdt_source (dispatch) and the format readers. */
#ifndef GDT_SOURCE_IMPL_H
#define GDT_SOURCE_IMPL_H

#include "gdt_source.h"

typedef struct gdt_source_vtable {
    /* Same contract as gdt_source_read. */
    gdt_status (*read)(gdt_source *src, gdt_src_point *buf, size_t cap, size_t *n,
                       gdt_error *err);
    /* Frees src->impl (not src itself). */
    void (*close)(gdt_source *src);
    /* Same contract as gdt_source_seek, 0 <= rec <= point count checked;
     * NULL where the format cannot start at a record. */
    gdt_status (*seek)(gdt_source *src, uint64_t rec, uint64_t end, gdt_error *err);
    /* Same contract as gdt_source_starts; NULL: none. */
    uint64_t (*starts)(const gdt_source *src, uint64_t *out, uint64_t cap);
    /* Same contract as gdt_source_read_raw; NULL: records are not LAS. */
    gdt_status (*read_raw)(gdt_source *src, gdt_src_point *buf, unsigned char *raw, size_t cap,
                           size_t *n, gdt_error *err);
} gdt_source_vtable;

struct gdt_source {
    const gdt_source_vtable *vt;
    void *impl;               /* reader-specific state, owned by the reader */
    gdt_source_info info;     /* filled by the reader's open */
    char *path;               /* owned by the dispatcher */
    gdt_source_opts opts;
};

/* Reader entry points.  Preconditions: src->path and src->opts are set,
 * everything else zero.  On success they set vt, impl and info.  On failure
 * they release what they allocated and leave vt == NULL. */
gdt_status gdt_las_open(gdt_source *src, gdt_error *err);
gdt_status gdt_pcd_open(gdt_source *src, gdt_error *err);

#endif
