/* gcd_scan.cl — exclusive prefix sums over uint arrays (stream compaction
 * and slot allocation in every phase of the gCD core).
 *
 * A scan of n values in place is three launches per level:
 *   scan_reduce  one work-item per chunk of `chunk` values writes the chunk sum;
 *   (the chunk sums are scanned recursively, or by scan_single when few);
 *   scan_down    one work-item per chunk rescans its chunk from its offset.
 * Results do not depend on the device or the work-group size.  Sums are
 * modulo 2^32; callers keep totals below 2^31.
 * CPU reference: the sequential exclusive scan in tests/c/test_gcd_kernels.c. */
#pragma OPENCL FP_CONTRACT OFF

__kernel void scan_reduce(__global const uint *data, uint doff, uint n, uint chunk,
                          __global uint *sums, uint soff)
{
    size_t g = get_global_id(0);
    size_t lo = g * (size_t)chunk;
    if (lo >= n)
        return;
    size_t hi = lo + chunk < n ? lo + chunk : n;
    uint s = 0;
    for (size_t i = lo; i < hi; i++)
        s += data[doff + i];
    sums[soff + g] = s;
}

/* One work-item: exclusive scan of data[doff .. doff+n) in place, total to
 * total[toff]. */
__kernel void scan_single(__global uint *data, uint doff, uint n, __global uint *total,
                          uint toff)
{
    if (get_global_id(0) != 0)
        return;
    uint s = 0;
    for (uint i = 0; i < n; i++) {
        uint v = data[doff + i];
        data[doff + i] = s;
        s += v;
    }
    total[toff] = s;
}

__kernel void scan_down(__global uint *data, uint doff, uint n, uint chunk,
                        __global const uint *offsets, uint ooff)
{
    size_t g = get_global_id(0);
    size_t lo = g * (size_t)chunk;
    if (lo >= n)
        return;
    size_t hi = lo + chunk < n ? lo + chunk : n;
    uint s = offsets[ooff + g];
    for (size_t i = lo; i < hi; i++) {
        uint v = data[doff + i];
        data[doff + i] = s;
        s += v;
    }
}

/* After an exclusive scan pos[] of 0/1 flags (total = sum): out[pos[i]] = i
 * for every flagged i (flag i is set iff the scan steps up after i). */
__kernel void compact_index(__global const uint *pos, uint n, uint total, __global uint *out)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    uint next = i + 1 < n ? pos[i + 1] : total;
    if (next != pos[i])
        out[pos[i]] = i;
}

/* ---- stable LSD radix sort of (key, value) pairs ----
 * One pass sorts by the 8-bit digit at shift: radix_hist counts the digits
 * of every chunk of `chunk` pairs into hist[digit * nchunks + chunk index];
 * after an exclusive scan of hist, radix_scatter moves each chunk's pairs in
 * order to their digit's next slot.  Chunks are walked in order by one
 * work-item each, so every pass is stable and the result deterministic.
 * CPU reference: a stable sort in tests/c/test_gcd_kernels.c. */
__kernel void radix_hist(__global const uint *keys, uint n, uint shift, uint chunk,
                         uint nchunks, __global uint *hist)
{
    uint g = get_global_id(0);
    if (g >= nchunks)
        return;
    uint cnt[256];
    for (int d = 0; d < 256; d++)
        cnt[d] = 0;
    size_t lo = (size_t)g * chunk, hi = lo + chunk < n ? lo + chunk : n;
    for (size_t i = lo; i < hi; i++)
        cnt[(keys[i] >> shift) & 255u]++;
    for (int d = 0; d < 256; d++)
        hist[(size_t)d * nchunks + g] = cnt[d];
}

__kernel void radix_scatter(__global const uint *keys, __global const uint *vals, uint n,
                            uint shift, uint chunk, uint nchunks, __global const uint *hist,
                            __global uint *okeys, __global uint *ovals)
{
    uint g = get_global_id(0);
    if (g >= nchunks)
        return;
    uint at[256];
    for (int d = 0; d < 256; d++)
        at[d] = hist[(size_t)d * nchunks + g];
    size_t lo = (size_t)g * chunk, hi = lo + chunk < n ? lo + chunk : n;
    for (size_t i = lo; i < hi; i++) {
        uint k = keys[i], p = at[(k >> shift) & 255u]++;
        okeys[p] = k;
        ovals[p] = vals[i];
    }
}

/* b[0..n) = v: large fills, spread over the compute units (the fill of
 * the OpenCL runtime may run on one thread). */
__kernel void fill_u32(__global uint *b, uint n, uint v)
{
    uint i = get_global_id(0);
    if (i < n)
        b[i] = v;
}
