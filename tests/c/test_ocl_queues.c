/* test_ocl_queues — several command queues of one device (gdt_ocl_create
 * with opts.share), each driven by a thread of its own, launch one kernel
 * at the same time over ranges that grow from launch to launch and differ
 * between the queues.  Every launch must compute what it should (each
 * queue reads its results back and checks every seventh item and the
 * last), and the runtime must neither fail nor abort.  PoCL's CPU drivers
 * before PoCL 7 abort in about a third of such rounds unless each queue
 * has programs of its own (gdt_ocl_queues_need_own_programs); NROUNDS
 * rounds, each with a kernel of its own name, so that a runtime with that
 * fault rarely passes (it aborted in 20 of 20 runs).  Exit 77 without an
 * OpenCL device. */
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_ocl.h"

#define NQUEUES 6
#define NROUNDS 6 /* kernels queue_fill_0 .. queue_fill_<NROUNDS-1> */
#define LOCAL 8
#define LAUNCHES 30
#define STEPS 4000 /* hash steps per item */

static gdt_checks checks;

typedef struct queue_job {
    gdt_ocl *ocl;
    gdt_ocl_program *prog;
    unsigned slot, round;
    unsigned long bad;               /* items with a wrong value */
    char failure[GDT_ERROR_MSG_MAX]; /* the first failed call, "" when none */
} queue_job;

/* What queue_fill.cl writes to item i. */
static uint32_t expected(uint32_t i, uint32_t salt)
{
    uint32_t v = i ^ salt;
    for (uint32_t r = 0; r < STEPS; r++)
        v = (v ^ (v >> 15)) * 2246822519u + r;
    return v;
}

/* Launch j of queue slot covers LOCAL * (NQUEUES * j + slot + 1) items: the
 * queues take turns at the next larger range, so a launch nearly always
 * asks for a range no launch of the kernel before it had. */
static size_t launch_items(unsigned slot, unsigned j)
{
    return (size_t)LOCAL * (NQUEUES * j + slot + 1);
}

static void *drive(void *arg)
{
    queue_job *q = arg;
    gdt_error err;
    gdt_ocl_kernel *k = NULL;
    gdt_ocl_buf *b = NULL;
    char kname[32];
    size_t cap = launch_items(q->slot, LAUNCHES - 1);
    uint32_t *host = malloc(cap * sizeof *host);

    memset(&err, 0, sizeof err);
    if (host == NULL) {
        snprintf(q->failure, sizeof q->failure, "out of memory");
        return NULL;
    }
    snprintf(kname, sizeof kname, "queue_fill_%u", q->round);
    if (gdt_ocl_kernel_get(q->prog, kname, &k, &err) != GDT_OK ||
        gdt_ocl_buf_create(q->ocl, cap * sizeof *host, "queue test", &b, &err) != GDT_OK)
        goto fail;
    for (unsigned j = 0; j < LAUNCHES; j++) {
        size_t n = launch_items(q->slot, j);
        uint32_t salt = (uint32_t)(q->slot * 1000003u + j);
        if (gdt_ocl_arg_buf(k, 0, b, &err) != GDT_OK ||
            gdt_ocl_arg_u32(k, 1, (uint32_t)n, &err) != GDT_OK ||
            gdt_ocl_arg_u32(k, 2, salt, &err) != GDT_OK ||
            gdt_ocl_arg_u32(k, 3, STEPS, &err) != GDT_OK ||
            gdt_ocl_run(q->ocl, k, n, LOCAL, &err) != GDT_OK)
            goto fail;
        /* every launch waits for its results and checks them, so the queue
         * is idle a while after each: a runtime that confuses the launches
         * of queues in flight together is caught when they end while the
         * other queues have nothing to start */
        if (gdt_ocl_read(q->ocl, b, 0, host, n * sizeof *host, &err) != GDT_OK)
            goto fail;
        /* a seventh of the items, each launch another seventh: checking all
         * on the host would take longer than the kernel */
        for (size_t i = j % 7; i < n; i += 7)
            q->bad += host[i] != expected((uint32_t)i, salt);
        q->bad += host[n - 1] != expected((uint32_t)(n - 1), salt);
    }
    gdt_ocl_buf_release(q->ocl, b);
    free(host);
    return NULL;
fail:
    snprintf(q->failure, sizeof q->failure, "%s", err.msg);
    if (b != NULL)
        gdt_ocl_buf_release(q->ocl, b);
    free(host);
    return NULL;
}

int main(void)
{
    gdt_ocl *ocl[NQUEUES] = {NULL};
    gdt_ocl_program *prog[NQUEUES] = {NULL};
    queue_job job[NQUEUES];
    pthread_t th[NQUEUES];
    gdt_error err;
    int status = 0;

    memset(&err, 0, sizeof err);
    for (unsigned s = 0; s < NQUEUES; s++) {
        gdt_ocl_opts o;
        memset(&o, 0, sizeof o);
        o.device = getenv("GDT_TEST_DEVICE");
        o.kernel_dir = GDT_TEST_QUEUE_KERNELS;
        o.share = ocl;
        o.nshare = s;
        if (gdt_ocl_create(&ocl[s], &o, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            status = s == 0 && err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
            goto done;
        }
        GDT_CHECK(&checks, gdt_ocl_is_shared_queue(ocl[s]) == (s > 0), "queue %u shared", s);
        if (gdt_ocl_build(ocl[s], "queue_fill.cl", NULL, &prog[s], &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            status = 1;
            goto done;
        }
    }
    printf("test_ocl_queues: %d queues of %s, %d rounds of %d launches each\n", NQUEUES,
           gdt_ocl_device_name(ocl[0]), NROUNDS, LAUNCHES);
    for (unsigned r = 0; r < NROUNDS; r++) {
        unsigned started = 0;
        memset(job, 0, sizeof job);
        for (unsigned s = 0; s < NQUEUES; s++) {
            job[s].ocl = ocl[s];
            job[s].prog = prog[s];
            job[s].slot = s;
            job[s].round = r;
            if (pthread_create(&th[s], NULL, drive, &job[s]) != 0)
                break;
            started++;
        }
        for (unsigned s = 0; s < started; s++)
            pthread_join(th[s], NULL);
        if (started < NQUEUES) {
            fprintf(stderr, "test_ocl_queues: cannot start a thread\n");
            status = 1;
            goto done;
        }
        for (unsigned s = 0; s < NQUEUES; s++) {
            GDT_CHECK(&checks, job[s].failure[0] == '\0', "round %u, queue %u: %s", r, s,
                      job[s].failure);
            GDT_CHECK(&checks, job[s].bad == 0, "round %u, queue %u: %lu wrong items", r, s,
                      job[s].bad);
        }
    }
done:
    for (unsigned s = NQUEUES; s-- > 0;)
        gdt_ocl_destroy(ocl[s]);
    if (status != 0)
        return status;
    return gdt_check_finish(&checks, "test_ocl_queues");
}
