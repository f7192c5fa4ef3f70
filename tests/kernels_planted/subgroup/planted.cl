/* Planted for the portability check: a builtin that OpenCL C 1.2 does not
 * have (sub-groups are OpenCL 2.1 or an extension). */
__kernel void planted(__global uint *out)
{
    out[get_global_id(0)] = get_sub_group_size();
}
