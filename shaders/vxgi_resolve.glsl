// VXGI resolve, one invocation per voxel fragment (only occupied voxels are touched: a dense pass over
// 128^3 voxels cost ~10x more). RESOLVE: the fixed-point sums of vxgi_inject.glsl become the mean
// outgoing radiance of the voxel's fragments, premultiplied by its coverage (1: a surface fell in the
// voxel), in mip level 0 of the RGBA16F grid; every fragment of a voxel stores the same value. ZERO
// (after RESOLVE): the voxel's sums are cleared for the next injection. CLEAR: the voxel is emptied
// (run on a fragment list before it is remade, so voxels its objects left do not keep their light).
#if defined COMPUTE_SHADER

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Counter { uint count; uint capacity; };
layout(std430, binding = 1) readonly buffer Fragments { vec4 frags[]; };
#include "vxgi_fixed.glsl"
layout(rgba16f, binding = 0) writeonly uniform image3D u_level0;

uniform int u_res;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= min(count, capacity)) return;
    uint voxel = floatBitsToUint(frags[3u * i].w);
    uint res = uint(u_res);
    ivec3 v = ivec3(voxel % res, (voxel / res) % res, voxel / (res * res));
    uint base = 8u * voxel;
#if defined RESOLVE
    uint n = max(sums[base + 6u], 1u);
    vec3 sum = vec3(fixed_value(base), fixed_value(base + 2u), fixed_value(base + 4u));
    imageStore(u_level0, v, vec4(sum / float(n), 1.0));
#elif defined ZERO
    for (uint k = 0u; k < 7u; ++k) sums[base + k] = 0u;
#elif defined CLEAR
    imageStore(u_level0, v, vec4(0.0));
#endif
}

#endif
