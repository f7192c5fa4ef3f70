/* Planted for the portability check: 128-bit integers compile for PoCL's
 * CPU device (and PTX, AMDGPU) but are not OpenCL C: SPIR refuses them. */
__kernel void planted(__global long *out, long a, long b)
{
    __int128 p = (__int128)a * (__int128)b;
    out[get_global_id(0)] = (long)(p >> 64);
}
