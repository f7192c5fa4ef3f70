/* Fuzz target of the tile-file (.tri) parser a resumed run and the merge
 * read (tr_tri_check_header, tr_tri_read_seam of tiler/private/
 * tiled_files.h): the input is a whole .tri file.
 *
 * The tile it is read for takes its vertex base, point count and job id
 * from the input's own header words (offsets 8, 16, 48 and 56; zero where
 * the input is shorter), so that seeds from a kept job and their mutations
 * reach the seam section; a mutated base or count then tests the id range.
 * The seam it is appended to already holds one vertex and one edge, which
 * must survive.
 *
 * It aborts when a failure is reported without its class and message, when
 * the status disagrees with the header verdict (6801 for a foreign file or
 * short header, 6802 for counts that do not add up to the size), or when an
 * accepted seam has other than the header's counts, an id outside
 * [base, base + points) or a coordinate outside [0, GDT_COORD_MAX].
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "gdt_seam.h"
#include "private/tiled_files.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static uint64_t word(const uint8_t *data, size_t size, size_t at)
{
    return at + 8 <= size ? tr_get_u64(data + at) : 0;
}

/* The seam an accepted file leaves: the sentinel entries first, then the
 * header's counts of entries in the tile's range and the frame. */
static void check_seam(const gdt_seam *s, const tr_tri_expect *ex, uint64_t nv, uint64_t ne)
{
    if (s->nv != 1 + nv || s->ne != 1 + ne || s->v[0].id != 7 || s->v[0].x != 1 ||
        s->v[0].y != 2 || s->e[0].a != 3 || s->e[0].b != 4)
        abort();
    for (size_t i = 1; i < s->nv; i++) {
        const gdt_seam_vertex *v = &s->v[i];
        if (v->id < ex->base || v->id - ex->base >= ex->points || v->x < 0 || v->y < 0 ||
            v->x > GDT_COORD_MAX || v->y > GDT_COORD_MAX)
            abort();
    }
    for (size_t i = 1; i < s->ne; i++) {
        const gdt_seam_edge *e = &s->e[i];
        if (e->a < ex->base || e->a - ex->base >= ex->points || e->b < ex->base ||
            e->b - ex->base >= ex->points)
            abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static unsigned char *scratch;
    const char *path = NULL;
    uint64_t job[2] = {word(data, size, 48), word(data, size, 56)};
    tr_tri_expect ex = {word(data, size, 8), word(data, size, 16), job, 0};
    tr_tri_verdict v = TR_TRI_FOREIGN;
    uint64_t nf = 0, nv = 0, ne = 0;
    gdt_seam s;
    gdt_error err;
    gdt_status st;
    FILE *f = NULL;

    if (scratch == NULL && (scratch = malloc(TR_SEAM_VERTEX * (size_t)TR_CHUNK)) == NULL)
        gdt_fuzz_die("scratch buffer");
    if (gdt_fuzz_memfile(data, size, &path) != 0 || (f = fopen(path, "rb")) == NULL)
        gdt_fuzz_die("input file");
    memset(&s, 0, sizeof s);
    s.v = malloc(sizeof *s.v);
    s.e = malloc(sizeof *s.e);
    if (s.v == NULL || s.e == NULL)
        gdt_fuzz_die("seam");
    s.cap_v = s.cap_e = s.nv = s.ne = 1;
    s.v[0] = (gdt_seam_vertex){.id = 7, .x = 1, .y = 2};
    s.e[0] = (gdt_seam_edge){.a = 3, .b = 4};
    if (size >= TR_HEADER)
        v = tr_tri_check_header(data, size, &ex, &nf, &nv, &ne);
    gdt_error_clear(&err);
    st = tr_tri_read_seam(f, size, &ex, &s, scratch, "fuzz.tri", &err);
    fclose(f);
    if (st == GDT_OK) {
        if (v != TR_TRI_FITS)
            abort();
        check_seam(&s, &ex, nv, ne);
    } else {
        gdt_fuzz_check_error(st, &err);
        /* a header that does not fit is refused with its own number; one
         * that fits can only fail on its content (or memory) */
        if ((v == TR_TRI_FOREIGN || v == TR_TRI_JOB) && err.code != 6801)
            abort();
        if (v == TR_TRI_SIZE && err.code != 6802)
            abort();
        if (v == TR_TRI_FITS && err.code != 6802 && err.code != 7001)
            abort();
    }
    free(s.v);
    free(s.e);
    return 0;
}
