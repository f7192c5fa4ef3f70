/* The job journal (see private/job.h). */
#include "private/job.h"

#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define JOB_SCHEMA 1

struct gdt_job {
    sqlite3 *db;
    char *path; /* for messages */
};

static char *db_path(const char *dir)
{
    size_t l = strlen(dir);
    char *p = malloc(l + 8);
    if (p != NULL) {
        memcpy(p, dir, l);
        memcpy(p + l, "/job.db", 8);
    }
    return p;
}

int gdt_job_exists(const char *dir)
{
    struct stat sb;
    char *p = db_path(dir);
    int r = p != NULL && stat(p, &sb) == 0 && S_ISREG(sb.st_mode);
    free(p);
    return r;
}

/* SQLite failures: a full disk or an I/O error is the user's GDT_EIO; a
 * file that is not our database is a job mismatch. */
static gdt_status db_error(gdt_job *j, const char *what, gdt_error *err)
{
    int code = sqlite3_extended_errcode(j->db) & 0xff;
    if (code == SQLITE_NOTADB || code == SQLITE_CORRUPT)
        return gdt_error_set(err, GDT_EJOB, 6901, "%s: not a usable job database (%s): %s",
                             j->path, what, sqlite3_errmsg(j->db));
    return gdt_error_set(err, GDT_EIO, 4902, "%s: %s failed: %s", j->path, what,
                         sqlite3_errmsg(j->db));
}

static gdt_status exec(gdt_job *j, const char *sql, gdt_error *err)
{
    if (sqlite3_exec(j->db, sql, NULL, NULL, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    return GDT_OK;
}

/* A damaged journal is refused before it is used: SQLite reads and even
 * writes a database whose pages are inconsistent without an error, so a
 * record written could read back other or missing.  quick_check walks
 * every page once (the journal is small: one row per tile). */
static gdt_status check_intact(gdt_job *j, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    int rc;
    if (sqlite3_prepare_v2(j->db, "PRAGMA quick_check(1)", -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "check", err);
    rc = sqlite3_step(s);
    if (rc == SQLITE_ROW) {
        const unsigned char *t = sqlite3_column_text(s, 0);
        if (t == NULL || strcmp((const char *)t, "ok") != 0)
            st = gdt_error_set(err, GDT_EJOB, 6901,
                               "%s: not a usable job database (damaged: %.200s); rerun with "
                               "--restart to discard it",
                               j->path, t != NULL ? (const char *)t : "no result");
    } else {
        st = db_error(j, "check", err);
    }
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_open(gdt_job **out, const char *dir, int create, int *is_new,
                        gdt_error *err)
{
    gdt_job *j = calloc(1, sizeof *j);
    gdt_status st;
    int existed;

    *out = NULL;
    if (j == NULL || (j->path = db_path(dir)) == NULL) {
        free(j);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    existed = gdt_job_exists(dir);
    if (!existed && !create) {
        st = gdt_error_set(err, GDT_EJOB, 6902, "%s: no job here (no job.db)", dir);
        goto fail;
    }
    if (sqlite3_open_v2(j->path, &j->db,
                        SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0), NULL) !=
        SQLITE_OK) {
        st = gdt_error_set(err, GDT_EIO, 4901, "%s: cannot open the job database: %s",
                           j->path, j->db != NULL ? sqlite3_errmsg(j->db) : "out of memory");
        goto fail;
    }
    sqlite3_busy_timeout(j->db, 5000);
    st = existed ? check_intact(j, err) : GDT_OK;
    if (st == GDT_OK)
        st = exec(j, "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;", err);
    if (st == GDT_OK)
        st = exec(j,
                  "CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);"
                  "CREATE TABLE IF NOT EXISTS stage(name TEXT PRIMARY KEY, done INTEGER NOT "
                  "NULL);"
                  "CREATE TABLE IF NOT EXISTS tile(k INTEGER PRIMARY KEY, file TEXT NOT NULL, "
                  "size INTEGER NOT NULL, checksum INTEGER NOT NULL);",
                  err);
    if (st != GDT_OK)
        goto fail;
    if (existed) {
        char *schema = NULL;
        st = gdt_job_get_meta(j, "schema", &schema, err);
        if (st == GDT_OK && (schema == NULL || atoi(schema) != JOB_SCHEMA))
            st = gdt_error_set(err, GDT_EJOB, 6901,
                               "%s: job database of another version (schema %s)", j->path,
                               schema != NULL ? schema : "none");
        free(schema);
        if (st != GDT_OK)
            goto fail;
    } else {
        char v[16];
        snprintf(v, sizeof v, "%d", JOB_SCHEMA);
        st = gdt_job_set_meta(j, "schema", v, err);
        if (st != GDT_OK)
            goto fail;
    }
    if (is_new != NULL)
        *is_new = !existed;
    *out = j;
    return GDT_OK;
fail:
    gdt_job_close(j);
    return st;
}

void gdt_job_close(gdt_job *j)
{
    if (j == NULL)
        return;
    sqlite3_close(j->db);
    free(j->path);
    free(j);
}

gdt_status gdt_job_get_meta(gdt_job *j, const char *key, char **value, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    int rc;
    *value = NULL;
    if (sqlite3_prepare_v2(j->db, "SELECT value FROM meta WHERE key = ?1", -1, &s, NULL) !=
        SQLITE_OK)
        return db_error(j, "query", err);
    sqlite3_bind_text(s, 1, key, -1, SQLITE_STATIC);
    rc = sqlite3_step(s);
    if (rc == SQLITE_ROW) {
        const unsigned char *t = sqlite3_column_text(s, 0);
        *value = strdup(t != NULL ? (const char *)t : "");
        if (*value == NULL)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    } else if (rc != SQLITE_DONE) {
        st = db_error(j, "query", err);
    }
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_set_meta(gdt_job *j, const char *key, const char *value, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    if (sqlite3_prepare_v2(j->db, "INSERT OR REPLACE INTO meta(key, value) VALUES (?1, ?2)", -1,
                           &s, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    sqlite3_bind_text(s, 1, key, -1, SQLITE_STATIC);
    sqlite3_bind_text(s, 2, value, -1, SQLITE_STATIC);
    if (sqlite3_step(s) != SQLITE_DONE)
        st = db_error(j, "update", err);
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_stage_done(gdt_job *j, const char *stage, int *done, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    int rc;
    *done = 0;
    if (sqlite3_prepare_v2(j->db, "SELECT done FROM stage WHERE name = ?1", -1, &s, NULL) !=
        SQLITE_OK)
        return db_error(j, "query", err);
    sqlite3_bind_text(s, 1, stage, -1, SQLITE_STATIC);
    rc = sqlite3_step(s);
    if (rc == SQLITE_ROW)
        *done = sqlite3_column_int(s, 0) != 0;
    else if (rc != SQLITE_DONE)
        st = db_error(j, "query", err);
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_set_stage(gdt_job *j, const char *stage, int done, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    if (sqlite3_prepare_v2(j->db, "INSERT OR REPLACE INTO stage(name, done) VALUES (?1, ?2)",
                           -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    sqlite3_bind_text(s, 1, stage, -1, SQLITE_STATIC);
    sqlite3_bind_int(s, 2, done);
    if (sqlite3_step(s) != SQLITE_DONE)
        st = db_error(j, "update", err);
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_get_tile(gdt_job *j, uint64_t k, int *found, uint64_t *size,
                            uint64_t *checksum, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    int rc;
    *found = 0;
    if (sqlite3_prepare_v2(j->db, "SELECT size, checksum FROM tile WHERE k = ?1", -1, &s,
                           NULL) != SQLITE_OK)
        return db_error(j, "query", err);
    sqlite3_bind_int64(s, 1, (sqlite3_int64)k);
    rc = sqlite3_step(s);
    if (rc == SQLITE_ROW) {
        *found = 1;
        *size = (uint64_t)sqlite3_column_int64(s, 0);
        *checksum = (uint64_t)sqlite3_column_int64(s, 1);
    } else if (rc != SQLITE_DONE) {
        st = db_error(j, "query", err);
    }
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_put_tile(gdt_job *j, uint64_t k, const char *file, uint64_t size,
                            uint64_t checksum, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    if (sqlite3_prepare_v2(j->db,
                           "INSERT OR REPLACE INTO tile(k, file, size, checksum) "
                           "VALUES (?1, ?2, ?3, ?4)",
                           -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    sqlite3_bind_int64(s, 1, (sqlite3_int64)k);
    sqlite3_bind_text(s, 2, file, -1, SQLITE_STATIC);
    sqlite3_bind_int64(s, 3, (sqlite3_int64)size);
    sqlite3_bind_int64(s, 4, (sqlite3_int64)checksum);
    if (sqlite3_step(s) != SQLITE_DONE)
        st = db_error(j, "update", err);
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_begin(gdt_job *j, gdt_error *err)
{
    return exec(j, "BEGIN IMMEDIATE", err);
}

gdt_status gdt_job_commit(gdt_job *j, gdt_error *err)
{
    gdt_status st = exec(j, "COMMIT", err);
    if (st != GDT_OK)
        sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
    return st;
}

gdt_status gdt_job_clear_tiles(gdt_job *j, gdt_error *err)
{
    return exec(j, "BEGIN; DELETE FROM tile; DELETE FROM stage WHERE name = 'ply'; COMMIT;",
                err);
}

static uint64_t rotl(uint64_t v, int r)
{
    return (v << r) | (v >> (64 - r));
}

/* The little-endian 64-bit word at b (any alignment). */
static uint64_t load_le64(const unsigned char *b)
{
    uint64_t w;
    memcpy(&w, b, sizeof w);
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    w = __builtin_bswap64(w);
#endif
    return w;
}

/* The hashes' common end: the tail bytes b[0..n), then the final mix. */
static uint64_t hash_finish(uint64_t h, const unsigned char *b, size_t n)
{
    const uint64_t k1 = UINT64_C(0x9e3779b185ebca87), k2 = UINT64_C(0xc2b2ae3d27d4eb4f),
                   k3 = UINT64_C(0x165667b19e3779f9);
    for (size_t i = 0; i < n; i++) {
        h ^= b[i] * k3;
        h = rotl(h, 11) * k1;
    }
    h ^= h >> 33;
    h *= k2;
    h ^= h >> 29;
    h *= k3;
    h ^= h >> 32;
    return h;
}

uint64_t gdt_hash64(const void *p, size_t n, uint64_t seed)
{
    const uint64_t k1 = UINT64_C(0x9e3779b185ebca87), k2 = UINT64_C(0xc2b2ae3d27d4eb4f),
                   k3 = UINT64_C(0x165667b19e3779f9);
    const unsigned char *b = p;
    uint64_t h = seed ^ ((uint64_t)n * k1);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t w = 0;
        for (int q = 7; q >= 0; q--)
            w = (w << 8) | b[i + (size_t)q];
        w *= k2;
        w = rotl(w, 31) * k1;
        h ^= w;
        h = rotl(h, 27) * k1 + k3;
    }
    return hash_finish(h, b + i, n - i);
}

/* Four gdt_hash64-style lanes over interleaved 8-byte words (word i goes to
 * lane i mod 4), so the multiply chains run side by side; the lanes, the
 * tail bytes and the length are then mixed into one value. */
uint64_t gdt_hash64_wide(const void *p, size_t n, uint64_t seed)
{
    const uint64_t k1 = UINT64_C(0x9e3779b185ebca87), k2 = UINT64_C(0xc2b2ae3d27d4eb4f),
                   k3 = UINT64_C(0x165667b19e3779f9);
    const unsigned char *b = p;
    uint64_t h0 = seed ^ ((uint64_t)n * k1), h1 = (seed + k3) ^ ((uint64_t)n * k1),
             h2 = (seed + 2 * k3) ^ ((uint64_t)n * k1), h3 = (seed + 3 * k3) ^ ((uint64_t)n * k1);
    uint64_t r;
    size_t i = 0;

    for (; i + 32 <= n; i += 32) {
        h0 = rotl(h0 ^ (rotl(load_le64(b + i) * k2, 31) * k1), 27) * k1 + k3;
        h1 = rotl(h1 ^ (rotl(load_le64(b + i + 8) * k2, 31) * k1), 27) * k1 + k3;
        h2 = rotl(h2 ^ (rotl(load_le64(b + i + 16) * k2, 31) * k1), 27) * k1 + k3;
        h3 = rotl(h3 ^ (rotl(load_le64(b + i + 24) * k2, 31) * k1), 27) * k1 + k3;
    }
    r = rotl(h0, 1) + rotl(h1, 7) + rotl(h2, 12) + rotl(h3, 18);
    return hash_finish(r, b + i, n - i);
}
