// VXGI light injection, one invocation per voxel fragment (vxgi_voxelize.glsl's list): the outgoing
// radiance of its surface, albedo / pi * E * |cos| * shadow (two-sided, as the G-buffer and Mitsuba's
// twosided BSDF shade) for one light, plus the emission once, added to its voxel's sums. The sums are
// 64-bit fixed point (32 fractional bits) built from 32-bit integer atomics with an explicit carry:
// integer addition is associative, so the grid is bitwise the same whatever order the objects are
// drawn and the fragments run in. DIRECTIONAL or POINT_LIGHT select the light; with neither, only
// emission and the fragment count are added. The shadow lookup is direct.glsl's own.
#if defined COMPUTE_SHADER

layout(local_size_x = 64) in;

#define SHADOW_LOOKUP 1
#include "direct.glsl"

layout(std430, binding = 0) readonly buffer Counter { uint count; uint capacity; };
layout(std430, binding = 1) readonly buffer Fragments { vec4 frags[]; };
// Per voxel: red lo/hi, green lo/hi, blue lo/hi, fragment count, unused.
layout(std430, binding = 2) buffer Sums { uint sums[]; };

uniform bool u_first;       // the first dispatch over this list: add emission and count the fragment

void add_fixed(uint at, float value) {
    float whole = floor(value);
    uint lo = uint((value - whole) * 4294967296.0);
    uint hi = uint(min(whole, 4294967295.0));
    uint old = atomicAdd(sums[at], lo);
    hi += (old + lo < old) ? 1u : 0u;   // the low word wrapped: carry into the high word
    if (hi != 0u) atomicAdd(sums[at + 1u], hi);
}

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
#if defined DIRECTIONAL
    vec3 l = -normalize(u_light_dir);
    vec3 e = u_light_color;
#else
    vec3 to_light = u_light_pos - p;
    float r2 = max(dot(to_light, to_light), 1e-12);
    vec3 l = to_light * inversesqrt(r2);
    vec3 e = u_light_color / r2;
#endif
    float cos_t = dot(n, l);
    if (cos_t < 0.0) { n = -n; cos_t = -cos_t; }   // the side that faces the light
    if (cos_t > 0.0) {
        float v = u_shadows ? visibility(p, n, cos_t) : 1.0;
        radiance += albedo / PI * e * (cos_t * v);
    }
#endif
    uint base = 8u * voxel;
    add_fixed(base, max(radiance.r, 0.0));
    add_fixed(base + 2u, max(radiance.g, 0.0));
    add_fixed(base + 4u, max(radiance.b, 0.0));
    if (u_first) atomicAdd(sums[base + 6u], 1u);
}

#endif
