// VXGI light injection, one invocation per voxel fragment (vxgi_voxelize.glsl's list): the outgoing
// radiance of its surface, albedo / pi * E * |cos| * shadow (two-sided, as the G-buffer and Mitsuba's
// twosided BSDF shade) for one light, plus the emission once, added to its voxel's fixed-point sums
// (vxgi_fixed.glsl: independent of draw order). DIRECTIONAL or POINT_LIGHT select the light; with neither, only
// emission and the fragment count are added. The shadow lookup is direct.glsl's own.
#if defined COMPUTE_SHADER

layout(local_size_x = 64) in;

#define SHADOW_LOOKUP 1
#include "direct.glsl"

layout(std430, binding = 0) readonly buffer Counter { uint count; uint capacity; };
layout(std430, binding = 1) readonly buffer Fragments { vec4 frags[]; };
#include "vxgi_fixed.glsl"

uniform bool u_first;       // the first dispatch over this list: add emission and count the fragment

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= min(count, capacity)) return;
    vec4 a = frags[3u * i], b = frags[3u * i + 1u], c = frags[3u * i + 2u];
    vec3 p = a.xyz;
    uint voxel = floatBitsToUint(a.w);
    vec3 albedo = vec3(unpackHalf2x16(floatBitsToUint(b.w)), unpackHalf2x16(floatBitsToUint(c.w)).x);
    vec3 radiance = u_first ? c.rgb : vec3(0.0);
#if defined DIRECTIONAL || defined POINT_LIGHT
    vec3 n = b.xyz;
    vec3 l, e;
    light_at(p, l, e);
    float cos_t = dot(n, l);
    if (cos_t < 0.0) { n = -n; cos_t = -cos_t; }   // the side that faces the light
    if (cos_t > 0.0) {
        float v = u_shadows ? visibility(p, n, cos_t) : 1.0;
        radiance += albedo / PI * e * (cos_t * v);
    }
#endif
    add_radiance(voxel, radiance);
    if (u_first) atomicAdd(sums[8u * voxel + 6u], 1u);
}

#endif
