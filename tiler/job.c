/* The job journal (see private/job.h). */
#define _GNU_SOURCE /* getrandom */
#include "private/job.h"

#include <errno.h>
#include <fcntl.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define JOB_SCHEMA 2

struct gdt_job {
    sqlite3 *db;
    char *path; /* for messages */
    uint64_t id[2];
};

/* malloc'd "<dir>/<name>", NULL when out of memory. */
static char *path_in(const char *dir, const char *name)
{
    size_t l = strlen(dir), m = strlen(name);
    char *p = malloc(l + m + 2);
    if (p != NULL) {
        memcpy(p, dir, l);
        p[l] = '/';
        memcpy(p + l + 1, name, m + 1);
    }
    return p;
}

static char *db_path(const char *dir)
{
    return path_in(dir, "job.db");
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
        return gdt_error_set(err, GDT_EJOB, 6901,
                             "%s: not a usable job database (%s): %s; rerun with --restart to "
                             "discard it",
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

/* The first column of the one-row query sql as an integer. */
static gdt_status query_int(gdt_job *j, const char *sql, int64_t *v, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    *v = 0;
    if (sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "query", err);
    if (sqlite3_step(s) == SQLITE_ROW)
        *v = sqlite3_column_int64(s, 0);
    else
        st = db_error(j, "query", err);
    sqlite3_finalize(s);
    return st;
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

/* 16 random bytes from the kernel; should it refuse, the clock, the pid and
 * an address mixed (distinct per job, which is what the id is for). */
static void random_id(uint64_t id[2])
{
    unsigned char b[16];
    ssize_t got = getrandom(b, sizeof b, 0);
    if (got == (ssize_t)sizeof b) {
        memcpy(id, b, sizeof b);
        return;
    }
    {
        struct timespec ts;
        uint64_t w[4];
        clock_gettime(CLOCK_REALTIME, &ts);
        w[0] = (uint64_t)ts.tv_sec;
        w[1] = (uint64_t)ts.tv_nsec;
        w[2] = (uint64_t)getpid();
        w[3] = (uint64_t)(uintptr_t)&ts;
        id[0] = gdt_hash64(w, sizeof w, 1);
        id[1] = gdt_hash64(w, sizeof w, 2);
    }
}

/* Inside the creating transaction: the schema row and a fresh id of a new
 * journal, or the checks of an existing one (fills j->id). */
static gdt_status init_meta(gdt_job *j, int create, int *fresh, gdt_error *err)
{
    char *schema = NULL, *id = NULL;
    int has = 0;
    gdt_status st = gdt_job_get_meta(j, "schema", &schema, err);
    *fresh = 0;
    /* a journal of another schema that finished nothing holds nothing to
     * lose: it is started afresh like an empty one */
    if (st == GDT_OK && schema != NULL && atoi(schema) != JOB_SCHEMA &&
        (st = gdt_job_has_work(j, &has, err)) == GDT_OK && !has && create) {
        free(schema);
        schema = NULL;
        st = exec(j, "DELETE FROM meta; DELETE FROM stage;", err);
    }
    if (st == GDT_OK && schema == NULL) {
        int64_t rows = 0;
        st = query_int(j,
                       "SELECT (SELECT COUNT(*) FROM meta) + (SELECT COUNT(*) FROM stage) + "
                       "(SELECT COUNT(*) FROM tile) + (SELECT COUNT(*) FROM pfile)",
                       &rows, err);
        if (st == GDT_OK && rows != 0)
            st = gdt_error_set(err, GDT_EJOB, 6901,
                               "%s: job database of another version (no schema); rerun with "
                               "--restart to discard it",
                               j->path);
        else if (st == GDT_OK && !create)
            st = gdt_error_set(err, GDT_EJOB, 6902, "%s: no job recorded there", j->path);
        if (st == GDT_OK) {
            char v[40];
            random_id(j->id);
            snprintf(v, sizeof v, "%d", JOB_SCHEMA);
            st = gdt_job_set_meta(j, "schema", v, err);
            snprintf(v, sizeof v, "%016llx%016llx", (unsigned long long)j->id[0],
                     (unsigned long long)j->id[1]);
            if (st == GDT_OK)
                st = gdt_job_set_meta(j, "id", v, err);
            *fresh = 1;
        }
    } else if (st == GDT_OK && atoi(schema) != JOB_SCHEMA) {
        st = gdt_error_set(err, GDT_EJOB, 6901,
                           "%s: job database of another version (schema %s); rerun with "
                           "--restart to discard it",
                           j->path, schema);
    } else if (st == GDT_OK) {
        char a[17], b[17];
        st = gdt_job_get_meta(j, "id", &id, err);
        if (st == GDT_OK &&
            (id == NULL || strlen(id) != 32 || strspn(id, "0123456789abcdef") != 32))
            st = gdt_error_set(err, GDT_EJOB, 6901,
                               "%s: the job database has no valid id; rerun with --restart to "
                               "discard it",
                               j->path);
        if (st == GDT_OK) {
            memcpy(a, id, 16);
            memcpy(b, id + 16, 16);
            a[16] = b[16] = '\0';
            j->id[0] = strtoull(a, NULL, 16);
            j->id[1] = strtoull(b, NULL, 16);
        }
    }
    free(schema);
    free(id);
    return st;
}

/* Removes a journal this process created and could not complete. */
static void remove_db_files(const char *dbpath)
{
    static const char *const ext[] = {"-wal", "-shm", "-journal", ""};
    size_t l = strlen(dbpath);
    char *p = malloc(l + 10);
    if (p == NULL)
        return;
    for (size_t i = 0; i < sizeof ext / sizeof ext[0]; i++) {
        memcpy(p, dbpath, l);
        memcpy(p + l, ext[i], strlen(ext[i]) + 1);
        unlink(p);
    }
    free(p);
}

gdt_status gdt_job_open(gdt_job **out, const char *dir, int create, int *is_new,
                        gdt_error *err)
{
    gdt_job *j = calloc(1, sizeof *j);
    gdt_status st;
    int existed, fresh = 0, in_tx = 0;

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
    /* tables, schema and id in one transaction: all of them or nothing */
    if (st == GDT_OK)
        st = exec(j, "BEGIN IMMEDIATE", err);
    in_tx = st == GDT_OK;
    if (st == GDT_OK)
        st = exec(j,
                  "CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);"
                  "CREATE TABLE IF NOT EXISTS stage(name TEXT PRIMARY KEY, done INTEGER NOT "
                  "NULL);"
                  "CREATE TABLE IF NOT EXISTS tile(k INTEGER PRIMARY KEY, file TEXT NOT NULL, "
                  "size INTEGER NOT NULL, checksum INTEGER NOT NULL);"
                  "CREATE TABLE IF NOT EXISTS pfile(k INTEGER NOT NULL, kind INTEGER NOT NULL, "
                  "size INTEGER NOT NULL, checksum INTEGER NOT NULL, PRIMARY KEY(k, kind));",
                  err);
    if (st == GDT_OK)
        st = init_meta(j, create, &fresh, err);
    if (st == GDT_OK)
        st = exec(j, "COMMIT", err);
    if (st != GDT_OK)
        goto fail;
    if (is_new != NULL)
        *is_new = fresh;
    *out = j;
    return GDT_OK;
fail:
    if (in_tx)
        sqlite3_exec(j->db, "ROLLBACK", NULL, NULL, NULL);
    {
        char *p = !existed && create ? strdup(j->path) : NULL;
        gdt_job_close(j);
        if (p != NULL)
            remove_db_files(p);
        free(p);
    }
    return st;
}

void gdt_job_id(const gdt_job *j, uint64_t id[2])
{
    id[0] = j->id[0];
    id[1] = j->id[1];
}

gdt_status gdt_job_has_work(gdt_job *j, int *has, gdt_error *err)
{
    int64_t n = 0;
    gdt_status st = query_int(j,
                              "SELECT (SELECT COUNT(*) FROM stage WHERE done != 0) + "
                              "(SELECT COUNT(*) FROM tile) + (SELECT COUNT(*) FROM pfile)",
                              &n, err);
    *has = n != 0;
    return st;
}

/* The content of an open lock file, "<pid> made|given\n" ("" if none). */
static void lock_content(int fd, char *b, size_t cap)
{
    ssize_t n = pread(fd, b, cap - 1, 0);
    b[n > 0 ? n : 0] = '\0';
}

gdt_status gdt_job_lock(const char *dir, int made, int *out, int *owned, gdt_error *err)
{
    char *p = path_in(dir, "lock");
    gdt_status st = GDT_OK;
    int fd = -1;

    *out = -1;
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    /* a finishing holder unlinks the file after its last use: a lock taken
     * on an unlinked file guards nothing, so it is taken again */
    for (int tries = 0; st == GDT_OK; tries++) {
        struct stat a, b;
        fd = open(p, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (fd < 0) {
            st = gdt_error_set(err, GDT_EIO, 4903, "%s: cannot create the lock file: %s", p,
                               strerror(errno));
            break;
        }
        if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
            if (errno == EWOULDBLOCK) {
                char holder[64];
                lock_content(fd, holder, sizeof holder);
                st = gdt_error_set(err, GDT_EJOB, 6906,
                                   "%s: another run (pid %ld) is using this job directory; "
                                   "wait until it ends, or use another --job",
                                   dir, strtol(holder, NULL, 10));
            } else {
                st = gdt_error_set(err, GDT_EIO, 4903, "%s: cannot lock: %s", p,
                                   strerror(errno));
            }
            break;
        }
        if (fstat(fd, &a) == 0 && stat(p, &b) == 0 && a.st_dev == b.st_dev &&
            a.st_ino == b.st_ino)
            break;
        close(fd);
        fd = -1;
        if (tries >= 100)
            st = gdt_error_set(err, GDT_EIO, 4903, "%s: the lock file keeps disappearing", p);
    }
    if (st == GDT_OK) {
        /* the file outlives the journal when a removal is cut short, so it
         * carries whether a run of this job made the directory */
        char b[64];
        int n;
        lock_content(fd, b, sizeof b);
        *owned = made || strstr(b, " made") != NULL;
        n = snprintf(b, sizeof b, "%ld %s\n", (long)getpid(), *owned ? "made" : "given");
        if (ftruncate(fd, 0) != 0 || pwrite(fd, b, (size_t)n, 0) != n)
            st = gdt_error_set(err, GDT_EIO, 4903, "%s: cannot write: %s", p, strerror(errno));
    }
    if (st != GDT_OK && fd >= 0)
        close(fd);
    else
        *out = fd;
    free(p);
    return st;
}

void gdt_job_unlock(const char *dir, int fd, int remove)
{
    if (fd < 0)
        return;
    if (remove) {
        char *p = path_in(dir, "lock");
        if (p != NULL)
            unlink(p);
        free(p);
    }
    close(fd);
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

/* The (size, checksum) row of query sql for ?1 = k and, when kind >= 0,
 * ?2 = kind; *found = 0 when there is none. */
static gdt_status get_record(gdt_job *j, const char *sql, uint64_t k, int kind, int *found,
                             uint64_t *size, uint64_t *checksum, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    gdt_status st = GDT_OK;
    int rc;
    *found = 0;
    if (sqlite3_prepare_v2(j->db, sql, -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "query", err);
    sqlite3_bind_int64(s, 1, (sqlite3_int64)k);
    if (kind >= 0)
        sqlite3_bind_int(s, 2, kind);
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

/* Binds ?1 = k, ?3 = size, ?4 = checksum to the prepared insert s (its ?2
 * is bound by the caller), runs and finalizes it. */
static gdt_status put_record(gdt_job *j, sqlite3_stmt *s, uint64_t k, uint64_t size,
                             uint64_t checksum, gdt_error *err)
{
    gdt_status st = GDT_OK;
    sqlite3_bind_int64(s, 1, (sqlite3_int64)k);
    sqlite3_bind_int64(s, 3, (sqlite3_int64)size);
    sqlite3_bind_int64(s, 4, (sqlite3_int64)checksum);
    if (sqlite3_step(s) != SQLITE_DONE)
        st = db_error(j, "update", err);
    sqlite3_finalize(s);
    return st;
}

gdt_status gdt_job_get_tile(gdt_job *j, uint64_t k, int *found, uint64_t *size,
                            uint64_t *checksum, gdt_error *err)
{
    return get_record(j, "SELECT size, checksum FROM tile WHERE k = ?1", k, -1, found, size,
                      checksum, err);
}

gdt_status gdt_job_put_tile(gdt_job *j, uint64_t k, const char *file, uint64_t size,
                            uint64_t checksum, gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    if (sqlite3_prepare_v2(j->db,
                           "INSERT OR REPLACE INTO tile(k, file, size, checksum) "
                           "VALUES (?1, ?2, ?3, ?4)",
                           -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    sqlite3_bind_text(s, 2, file, -1, SQLITE_STATIC);
    return put_record(j, s, k, size, checksum, err);
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
    return exec(j,
                "BEGIN; DELETE FROM tile; DELETE FROM pfile WHERE kind IN (1, 2); DELETE FROM stage "
                "WHERE name = 'ply'; COMMIT;",
                err);
}

gdt_status gdt_job_get_file(gdt_job *j, uint64_t k, int kind, int *found, uint64_t *size,
                            uint64_t *checksum, gdt_error *err)
{
    return get_record(j, "SELECT size, checksum FROM pfile WHERE k = ?1 AND kind = ?2", k, kind,
                      found, size, checksum, err);
}

gdt_status gdt_job_put_file(gdt_job *j, uint64_t k, int kind, uint64_t size, uint64_t checksum,
                            gdt_error *err)
{
    sqlite3_stmt *s = NULL;
    if (sqlite3_prepare_v2(j->db,
                           "INSERT OR REPLACE INTO pfile(k, kind, size, checksum) "
                           "VALUES (?1, ?2, ?3, ?4)",
                           -1, &s, NULL) != SQLITE_OK)
        return db_error(j, "update", err);
    sqlite3_bind_int(s, 2, kind);
    return put_record(j, s, k, size, checksum, err);
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
 * length and the tail bytes are then mixed into one value.  The length
 * enters only at the end, so the checksum of a file can be computed as it
 * is written, before its length is known. */
void gdt_hash_wide_init(gdt_hash_wide *s, uint64_t seed)
{
    const uint64_t k3 = UINT64_C(0x165667b19e3779f9);
    s->h[0] = seed;
    s->h[1] = seed + k3;
    s->h[2] = seed + 2 * k3;
    s->h[3] = seed + 3 * k3;
    s->n = 0;
}

/* The lanes over the whole 32-byte blocks of b[0..n); returns the bytes
 * consumed (a multiple of 32). */
static size_t wide_blocks(uint64_t h[4], const unsigned char *b, size_t n)
{
    const uint64_t k1 = UINT64_C(0x9e3779b185ebca87), k2 = UINT64_C(0xc2b2ae3d27d4eb4f),
                   k3 = UINT64_C(0x165667b19e3779f9);
    uint64_t h0 = h[0], h1 = h[1], h2 = h[2], h3 = h[3];
    size_t i = 0;
    for (; i + 32 <= n; i += 32) {
        h0 = rotl(h0 ^ (rotl(load_le64(b + i) * k2, 31) * k1), 27) * k1 + k3;
        h1 = rotl(h1 ^ (rotl(load_le64(b + i + 8) * k2, 31) * k1), 27) * k1 + k3;
        h2 = rotl(h2 ^ (rotl(load_le64(b + i + 16) * k2, 31) * k1), 27) * k1 + k3;
        h3 = rotl(h3 ^ (rotl(load_le64(b + i + 24) * k2, 31) * k1), 27) * k1 + k3;
    }
    h[0] = h0;
    h[1] = h1;
    h[2] = h2;
    h[3] = h3;
    return i;
}

void gdt_hash_wide_update(gdt_hash_wide *s, const void *p, size_t n)
{
    const unsigned char *b = p;
    size_t have = (size_t)(s->n % 32), used;
    s->n += n;
    if (have > 0) {
        size_t take = 32 - have < n ? 32 - have : n;
        memcpy(s->part + have, b, take);
        b += take;
        n -= take;
        if (have + take < 32)
            return;
        wide_blocks(s->h, s->part, 32);
    }
    used = wide_blocks(s->h, b, n);
    memcpy(s->part, b + used, n - used);
}

uint64_t gdt_hash_wide_final(const gdt_hash_wide *s)
{
    const uint64_t k1 = UINT64_C(0x9e3779b185ebca87);
    uint64_t r = rotl(s->h[0], 1) + rotl(s->h[1], 7) + rotl(s->h[2], 12) + rotl(s->h[3], 18);
    return hash_finish(r ^ (s->n * k1), s->part, (size_t)(s->n % 32));
}

uint64_t gdt_hash64_wide(const void *p, size_t n, uint64_t seed)
{
    gdt_hash_wide s;
    gdt_hash_wide_init(&s, seed);
    gdt_hash_wide_update(&s, p, n);
    return gdt_hash_wide_final(&s);
}

uint64_t gdt_job_file_seed(const uint64_t id[2], uint64_t k, int kind)
{
    unsigned char b[32];
    const uint64_t w[4] = {id[0], id[1], k, (uint64_t)kind};
    for (int i = 0; i < 4; i++)
        for (int q = 0; q < 8; q++)
            b[8 * i + q] = (unsigned char)(w[i] >> (8 * q));
    return gdt_hash64(b, sizeof b, UINT64_C(0x6764742d6a6f6273));
}
