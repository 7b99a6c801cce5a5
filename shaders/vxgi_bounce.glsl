// VXGI second bounce, one invocation per voxel fragment: the cones of vxgi_cone.glsl gather the
// first-bounce grid about the fragment's normal, and albedo * indirect is added to its voxel's sums
// (which still hold the direct light); resolving and filtering again gives a grid lit by two bounces.
#if defined COMPUTE_SHADER

layout(local_size_x = 64) in;

#include "vxgi_cone.glsl"
#include "vxgi_fixed.glsl"

layout(std430, binding = 0) readonly buffer Counter { uint count; uint capacity; };
layout(std430, binding = 1) readonly buffer Fragments { vec4 frags[]; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= min(count, capacity)) return;
    vec4 a = frags[3u * i], b = frags[3u * i + 1u], c = frags[3u * i + 2u];
    vec3 albedo = vec3(unpackHalf2x16(floatBitsToUint(b.w)), unpackHalf2x16(floatBitsToUint(c.w)).x);
    if (max(albedo.r, max(albedo.g, albedo.b)) <= 0.0) return;
    add_radiance(floatBitsToUint(a.w), albedo * gather(a.xyz, b.xyz).rgb);
}

#endif
