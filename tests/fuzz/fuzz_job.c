/* Fuzz target of the job-state loader (tiler/private/job.h): the input is
 * a job.db, opened as a resume opens it (no creation), then every record
 * the tiled run reads is queried — the schema, "params", "fingerprint",
 * both stages, tile records — and one transaction of the updates a run
 * makes is attempted, as a resumed run would on a damaged journal.
 *
 * Each input gets a fresh copy in a private folder (the write-ahead log
 * and shared-memory files of the previous input are removed first).  A
 * failure must come back as a status with its message, never as a crash;
 * values read must be terminated strings, flags 0 or 1, and a committed
 * record must read back as written.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "private/job.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const char *const meta_keys[] = {"schema", "params", "fingerprint"};
static const char *const stages[] = {"pass2", "ply"};
/* Tile keys a run asks for: the first ones, and keys at the ends of the
 * 64-bit range (stored as SQLite's signed integers). */
static const uint64_t tile_keys[] = {0, 1, 2, 3, 7, 255, (uint64_t)1 << 31,
                                     (uint64_t)1 << 63, UINT64_MAX};

static void clear_dir(const char *dir)
{
    gdt_fuzz_remove(dir, "job.db-wal");
    gdt_fuzz_remove(dir, "job.db-shm");
    gdt_fuzz_remove(dir, "job.db-journal");
}

/* Runs the queries; stops at the first failure, which must be reported. */
static void query(gdt_job *j)
{
    gdt_error err;
    gdt_status st = GDT_OK;
    volatile size_t sink = 0;

    gdt_error_clear(&err);
    for (size_t i = 0; st == GDT_OK && i < sizeof meta_keys / sizeof meta_keys[0]; i++) {
        char *v = NULL;
        st = gdt_job_get_meta(j, meta_keys[i], &v, &err);
        if (v != NULL)
            sink += strlen(v); /* a terminated string */
        free(v);
    }
    for (size_t i = 0; st == GDT_OK && i < sizeof stages / sizeof stages[0]; i++) {
        int done = -1;
        st = gdt_job_stage_done(j, stages[i], &done, &err);
        if (st == GDT_OK && done != 0 && done != 1)
            abort();
    }
    for (size_t i = 0; st == GDT_OK && i < sizeof tile_keys / sizeof tile_keys[0]; i++) {
        int found = -1;
        uint64_t sz = 0, sum = 0;
        st = gdt_job_get_tile(j, tile_keys[i], &found, &sz, &sum, &err);
        if (st == GDT_OK && found != 0 && found != 1)
            abort();
    }
    if (st == GDT_OK)
        st = gdt_job_begin(j, &err);
    if (st == GDT_OK)
        st = gdt_job_put_tile(j, 4, "tile_0_4.tri", 64, 0x0123456789abcdefu, &err);
    if (st == GDT_OK)
        st = gdt_job_set_stage(j, "pass2", 1, &err);
    if (st == GDT_OK)
        st = gdt_job_commit(j, &err);
    if (st == GDT_OK) {
        int found = 0;
        uint64_t sz = 0, sum = 0;
        st = gdt_job_get_tile(j, 4, &found, &sz, &sum, &err);
        /* a committed record reads back as written */
        if (st == GDT_OK && (!found || sz != 64 || sum != 0x0123456789abcdefu))
            abort();
    }
    if (st != GDT_OK)
        gdt_fuzz_check_error(st, &err);
    (void)sink;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *dir = NULL;
    gdt_job *j = NULL;
    gdt_error err;
    int is_new = -1;
    gdt_status st;

    if (gdt_fuzz_workdir(&dir) != 0)
        gdt_fuzz_die("work folder");
    clear_dir(dir);
    if (gdt_fuzz_write_file(dir, "job.db", data, size) != 0)
        gdt_fuzz_die("job.db");
    gdt_error_clear(&err);
    st = gdt_job_open(&j, dir, 0, &is_new, &err);
    if (st != GDT_OK) {
        if (j != NULL)
            abort();
        gdt_fuzz_check_error(st, &err);
        return 0;
    }
    if (is_new != 0)
        abort(); /* the file was there */
    query(j);
    gdt_job_close(j);
    return 0;
}
