/* Unit tests of the replay file of decoded points (io/private/replay.c):
 * records come back bit for bit, coordinates rebuilt exactly as the LAS
 * reader builds them, per input and in order; an abandoned input is not
 * replayable and does not disturb the inputs around it. */
#include "gdt_check.h"
#include "private/replay.h"

#include <string.h>

static gdt_checks checks;

static gdt_src_point make_point(uint64_t *rng, const double scale[3], const double offset[3])
{
    gdt_src_point p;
    memset(&p, 0, sizeof p);
    p.X = (int32_t)(uint32_t)gdt_splitmix64(rng);
    p.Y = (int32_t)(uint32_t)gdt_splitmix64(rng);
    p.Z = (int32_t)(uint32_t)gdt_splitmix64(rng);
    p.x = (double)p.X * scale[0] + offset[0];
    p.y = (double)p.Y * scale[1] + offset[1];
    p.z = (double)p.Z * scale[2] + offset[2];
    uint64_t a = gdt_splitmix64(rng);
    p.cls = (uint8_t)a;
    p.ret = (uint8_t)(a >> 8);
    p.nret = (uint8_t)(a >> 16);
    p.flags = (uint8_t)(a >> 24);
    return p;
}

static int same_point(const gdt_src_point *a, const gdt_src_point *b)
{
    return a->X == b->X && a->Y == b->Y && a->Z == b->Z &&
           memcmp(&a->x, &b->x, sizeof a->x) == 0 && memcmp(&a->y, &b->y, sizeof a->y) == 0 &&
           memcmp(&a->z, &b->z, sizeof a->z) == 0 && a->cls == b->cls && a->ret == b->ret &&
           a->nret == b->nret && a->flags == b->flags;
}

/* Reads input back in reads of cap and compares with want[0..n). */
static void check_input(gdt_replay *r, size_t input, uint64_t lo, const gdt_src_point *want,
                        size_t n, size_t cap, const double scale[3], const double offset[3])
{
    static gdt_src_point buf[70000];
    gdt_error err;
    size_t got = 0, k;

    gdt_error_clear(&err);
    GDT_CHECK(&checks, gdt_replay_has(r, input, lo, lo + n), "input %zu replayable", input);
    GDT_CHECK(&checks, gdt_replay_start(r, input, scale, offset, &err) == GDT_OK, "%s", err.msg);
    do {
        k = 0;
        GDT_CHECK(&checks, gdt_replay_read(r, buf, cap, &k, &err) == GDT_OK, "%s", err.msg);
        for (size_t i = 0; i < k && got + i < n; i++)
            GDT_CHECK_QUIET_AFTER(&checks, 5, same_point(&buf[i], &want[got + i]),
                                  "input %zu record %zu", input, got + i);
        got += k;
    } while (k > 0);
    GDT_CHECK(&checks, got == n, "input %zu: %zu records back, %zu written", input, got, n);
}

int main(int argc, char **argv)
{
    static gdt_src_point a[100000], c[3];
    const double scale[3] = {0.01, 0.001, 0.0025}, offset[3] = {500000.5, -4e6, 12.25};
    const double scale2[3] = {1e-7, 1e-7, 0.01}, offset2[3] = {-123.0, 45.0, 0.0};
    uint64_t rng = 42;
    gdt_replay *r = NULL;
    gdt_error err;

    gdt_error_clear(&err);
    GDT_CHECK(&checks, gdt_replay_open(&r, argc > 1 ? argv[1] : ".", &err) == GDT_OK, "%s",
              err.msg);
    if (r == NULL)
        return gdt_check_finish(&checks, "replay");
    for (size_t i = 0; i < 100000; i++)
        a[i] = make_point(&rng, scale, offset);
    for (size_t i = 0; i < 3; i++)
        c[i] = make_point(&rng, scale2, offset2);

    /* input 0: 100,000 records (several buffer refills), written unevenly */
    gdt_replay_begin(r, 0, 0, 100000);
    gdt_replay_append(r, a, 1);
    gdt_replay_append(r, a + 1, 65535);
    gdt_replay_append(r, a + 65536, 100000 - 65536);
    GDT_CHECK(&checks, !gdt_replay_has(r, 0, 0, 100000), "not replayable before its end");
    gdt_replay_end(r);
    /* input 1: abandoned half way */
    gdt_replay_begin(r, 1, 0, 1000);
    gdt_replay_append(r, a, 500);
    gdt_replay_abandon(r);
    /* input 2: a share of three records (7..9), another lattice; input 3:
     * empty */
    gdt_replay_begin(r, 2, 7, 10);
    gdt_replay_append(r, c, 3);
    gdt_replay_end(r);
    gdt_replay_begin(r, 3, 0, 0);
    gdt_replay_end(r);
    /* an input is never written twice */
    gdt_replay_begin(r, 2, 0, 10);
    gdt_replay_append(r, a, 10);
    gdt_replay_end(r);

    GDT_CHECK(&checks, gdt_replay_failed(r) == NULL, "%s", gdt_replay_failed(r));
    GDT_CHECK(&checks, !gdt_replay_has(r, 1, 0, 1000), "an abandoned input is not replayable");
    GDT_CHECK(&checks, !gdt_replay_has(r, 4, 0, 0), "an input never begun is not replayable");
    /* another range of an input is not what the replay holds */
    GDT_CHECK(&checks, !gdt_replay_has(r, 2, 0, 10) && !gdt_replay_has(r, 2, 7, 9),
              "a share replays only its own records");
    GDT_CHECK(&checks, !gdt_replay_has(r, 0, 0, 99999), "nor a whole input a part of it");
    check_input(r, 0, 0, a, 100000, 4096, scale, offset);
    check_input(r, 2, 7, c, 3, 2, scale2, offset2);
    check_input(r, 3, 0, c, 0, 16, scale2, offset2);
    check_input(r, 0, 0, a, 100000, 70000, scale, offset); /* again, other read sizes */
    GDT_CHECK(&checks, gdt_replay_start(r, 1, scale, offset, &err) == GDT_EINTERNAL,
              "starting an abandoned input is an internal error");
    gdt_replay_close(r);
    return gdt_check_finish(&checks, "replay");
}
