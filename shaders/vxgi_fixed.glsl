// VXGI per-voxel sums in 64-bit fixed point (32 fractional bits) built from 32-bit integer atomics
// with an explicit carry. Integer addition is associative, so the sums, and the grid resolved from
// them, are bitwise the same whatever order objects are drawn and fragments run in.
// Per voxel: red lo/hi, green lo/hi, blue lo/hi, fragment count, unused.
layout(std430, binding = 2) buffer Sums { uint sums[]; };

void add_fixed(uint at, float value) {
    float whole = floor(value);
    uint lo = uint((value - whole) * 4294967296.0);
    uint hi = uint(min(whole, 4294967295.0));
    uint old = atomicAdd(sums[at], lo);
    hi += (old + lo < old) ? 1u : 0u;   // the low word wrapped: carry into the high word
    if (hi != 0u) atomicAdd(sums[at + 1u], hi);
}

void add_radiance(uint voxel, vec3 radiance) {
    uint base = 8u * voxel;
    add_fixed(base, max(radiance.r, 0.0));
    add_fixed(base + 2u, max(radiance.g, 0.0));
    add_fixed(base + 4u, max(radiance.b, 0.0));
}

float fixed_value(uint at) {
    return float(sums[at + 1u]) + float(sums[at]) * (1.0 / 4294967296.0);
}
