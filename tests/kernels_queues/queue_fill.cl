/* Kernels for the command-queue test (tests/c/test_ocl_queues.c): item i
 * of n gets a value made from i and the launch's salt by rounds steps of
 * a multiplicative hash (the steps only make a launch last a while).  The
 * same kernel under several names: each name is a kernel the runtime
 * compiles and caches apart, so each round of the test starts afresh. */
#define QUEUE_FILL(name)                                                       \
    __kernel void name(__global uint *out, uint n, uint salt, uint rounds)     \
    {                                                                          \
        uint i = (uint)get_global_id(0);                                       \
        uint v = i ^ salt;                                                     \
        if (i >= n)                                                            \
            return;                                                            \
        for (uint r = 0; r < rounds; r++)                                      \
            v = (v ^ (v >> 15)) * 2246822519u + r;                             \
        out[i] = v;                                                            \
    }

QUEUE_FILL(queue_fill_0)
QUEUE_FILL(queue_fill_1)
QUEUE_FILL(queue_fill_2)
QUEUE_FILL(queue_fill_3)
QUEUE_FILL(queue_fill_4)
QUEUE_FILL(queue_fill_5)
