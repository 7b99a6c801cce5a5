// VXGI resolve, one invocation per voxel: the fixed-point sums of vxgi_inject.glsl become the mean
// outgoing radiance of the voxel's fragments, stored premultiplied by coverage (1 where any surface
// fell in the voxel, 0 elsewhere) in mip level 0 of the RGBA16F grid; the sums are zeroed for the next
// injection.
#if defined COMPUTE_SHADER

layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;

layout(std430, binding = 2) buffer Sums { uint sums[]; };
layout(rgba16f, binding = 0) writeonly uniform image3D u_level0;

uniform int u_res;

float fixed_value(uint at) {
    return float(sums[at + 1u]) + float(sums[at]) * (1.0 / 4294967296.0);
}

void main() {
    ivec3 v = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(v, ivec3(u_res)))) return;
    uint base = 8u * uint(v.x + u_res * (v.y + u_res * v.z));
    uint n = sums[base + 6u];
    vec4 voxel = vec4(0.0);
    if (n > 0u) {
        vec3 sum = vec3(fixed_value(base), fixed_value(base + 2u), fixed_value(base + 4u));
        voxel = vec4(sum / float(n), 1.0);
        for (uint k = 0u; k < 7u; ++k) sums[base + k] = 0u;
    }
    imageStore(u_level0, v, voxel);
}

#endif
