/* Fuzz target of the streaming point sources (gdt_source.h): the LAS reader
 * (built with GDT_FUZZ_FORMAT=1) or the PCD reader (GDT_FUZZ_FORMAT=2);
 * with GDT_FUZZ_FORMAT=1 and GDT_FUZZ_LAZ=1 (fuzz_lazfile), whole LAZ files
 * through the LAS reader and the LAZ stream (LAS files whose
 * point format byte has the compression bits; the LAS target skips them).
 * The LAZ target also derives the decoder thread count (0 to 3) and the
 * fields needed from the input, so the workers and the selective decoding
 * are exercised too.
 *
 * Each input is opened as a file, its header validated, every info field
 * read, and every point streamed to the end or to the first error; for a
 * third of the LAS and LAZ inputs (by length) through gdt_source_read_raw,
 * whose records must hold the X, Y, Z of their points.  Inputs
 * of the other format are skipped, so each target spends its time on its
 * own reader.  The read-buffer size and the chunk size are derived from the
 * input length, so refills and records that straddle them are exercised
 * without a format of the harness's own.  Work per input is bounded: a
 * point cap stops a file whose header promises more than the fuzzer's
 * max_len can hold (that is the reader's check to make, met long before
 * the cap on any input of a few kilobytes).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "gdt_source.h"

#ifndef GDT_FUZZ_FORMAT
#error "GDT_FUZZ_FORMAT must be 1 (LAS) or 2 (PCD)"
#endif

#ifndef GDT_FUZZ_LAZ
#define GDT_FUZZ_LAZ 0
#endif

#define FUZZ_MAX_POINTS ((uint64_t)1 << 22)
#define FUZZ_CHUNK_MAX 257

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The info fields, read so that a dangling string or an uninitialised
 * field shows under the sanitizers. */
static size_t touch_info(const gdt_source_info *in)
{
    size_t t = strlen(in->format_name) + strlen(in->version) + strlen(in->encoding);
    if (in->crs_desc == NULL)
        abort(); /* documented as never NULL */
    t += strlen(in->crs_desc);
    if (in->crs_wkt != NULL)
        t += strlen(in->crs_wkt);
    t += (size_t)in->point_count + in->point_format + in->record_length + in->extra_bytes +
         in->vlr_count + in->evlr_count + (size_t)in->epsg;
    return t;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static gdt_src_point buf[FUZZ_CHUNK_MAX];
    const char *path = NULL;
    gdt_source_opts opts;
    gdt_log log;
    gdt_error err;
    gdt_source *src = NULL;
    gdt_format fmt = GDT_FORMAT_UNKNOWN;
    uint64_t total = 0;
    volatile double sink = 0;
    volatile size_t info_sink;
    size_t chunk = 1 + size % FUZZ_CHUNK_MAX;
    unsigned char *raw = NULL;
    gdt_status st;

    if (gdt_fuzz_memfile(data, size, &path) != 0)
        gdt_fuzz_die("memory file");
    gdt_error_clear(&err);
    if (gdt_source_sniff(path, &fmt, &err) != GDT_OK || fmt != (gdt_format)GDT_FUZZ_FORMAT)
        return 0;
    if (GDT_FUZZ_FORMAT == 1 && (size > 104 && (data[104] & 0xc0u) != 0) != GDT_FUZZ_LAZ)
        return 0; /* LAZ to the LAZ target, the rest to the LAS one */
    memset(&opts, 0, sizeof opts);
    if (GDT_FUZZ_LAZ) {
        opts.threads = (int)(size % 4);
        opts.need = (unsigned)(size / 4 % 8);
    }
    gdt_log_init(&log, -1); /* warnings counted, not printed */
    opts.log = &log;
    /* 64 .. 4159 bytes: small enough that most inputs need several refills. */
    opts.buffer_bytes = 64 + (size * 2654435761u) % 4096;
    st = gdt_source_open(&src, path, &opts, &err);
    if (st != GDT_OK) {
        if (src != NULL)
            abort(); /* a failed open returns no source */
        gdt_fuzz_check_error(st, &err);
        return 0;
    }
    info_sink = touch_info(gdt_source_get_info(src));
    (void)info_sink;
    if (GDT_FUZZ_FORMAT == 1 && size % 3 == 0) {
        unsigned rl = gdt_source_get_info(src)->record_length;
        if (rl >= 12 && (raw = malloc((size_t)rl * chunk)) == NULL)
            gdt_fuzz_die("record buffer");
    }
    while (total < FUZZ_MAX_POINTS) {
        size_t n = 0;
        st = raw != NULL ? gdt_source_read_raw(src, buf, raw, chunk, &n, &err)
                         : gdt_source_read(src, buf, chunk, &n, &err);
        if (st != GDT_OK) {
            gdt_fuzz_check_error(st, &err);
            break;
        }
        if (n > chunk)
            abort(); /* more points than asked for */
        if (n == 0) {
            /* the end: it stays the end */
            if (gdt_source_read(src, buf, chunk, &n, &err) != GDT_OK || n != 0)
                abort();
            break;
        }
        for (size_t i = 0; i < n; i++)
            sink += buf[i].x + buf[i].y + buf[i].z + buf[i].X + buf[i].Y + buf[i].Z;
        for (size_t i = 0; raw != NULL && i < n; i++) {
            const unsigned char *r = raw + i * gdt_source_get_info(src)->record_length;
            int32_t v[3];
            for (int k = 0; k < 3; k++)
                v[k] = (int32_t)((uint32_t)r[4 * k] | (uint32_t)r[4 * k + 1] << 8 |
                                 (uint32_t)r[4 * k + 2] << 16 | (uint32_t)r[4 * k + 3] << 24);
            if (v[0] != buf[i].X || v[1] != buf[i].Y || v[2] != buf[i].Z)
                abort(); /* the record is not the point's */
        }
        total += n;
    }
    (void)sink;
    free(raw);
    gdt_source_close(src);
        return 0;
}
