// Packs the G-buffer into the neural model's input: float32 NHWC (depth, normal xyz, albedo rgb,
// direct rgb), rows top first, in one storage buffer, so the CPU reads it once and reshuffles nothing.
#if defined COMPUTE_SHADER

layout(local_size_x = 8, local_size_y = 8) in;

uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform sampler2D u_albedo;
uniform sampler2D u_direct;
uniform ivec2 u_size;

layout(std430, binding = 0) writeonly buffer Packed { float data[]; };

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= u_size.x || p.y >= u_size.y) return;
    int base = ((u_size.y - 1 - p.y) * u_size.x + p.x) * 10;
    vec3 n = texelFetch(u_normal, p, 0).xyz;
    vec3 a = texelFetch(u_albedo, p, 0).rgb;
    vec3 d = texelFetch(u_direct, p, 0).rgb;
    data[base] = texelFetch(u_depth, p, 0).r;
    data[base + 1] = n.x; data[base + 2] = n.y; data[base + 3] = n.z;
    data[base + 4] = a.r; data[base + 5] = a.g; data[base + 6] = a.b;
    data[base + 7] = d.r; data[base + 8] = d.g; data[base + 9] = d.b;
}

#endif
