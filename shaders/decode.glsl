// The lean path's decoding (diviewer.contract.lean): the generator's raw output (binding 1, float32 NCHW over the padded
// size, the frame at u_pad) to the radiance the exported graph gives, per GI texel, into u_radiance (rows top
// first, as the graph path's uploaded output): sign(y) (exp(|y| log(1 + radiance_max)) - 1) u_out_k (1 /
// exposure, the frame's light scale and the albedo floor's 1/2 folded in); unless FULL, times max(2 albedo - 1,
// 2 floor - 1) + 1 with DIVIDE_ALBEDO, plus the raw direct light (a NaN there stays NaN); never below 0.
#if defined COMPUTE_SHADER

layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 0) readonly buffer Packed { float data[]; };  // the raw inputs (pack.glsl)
layout(std430, binding = 1) readonly buffer Raw { float raw[]; };
layout(rgba32f, binding = 0) writeonly uniform image2D u_radiance;
uniform ivec2 u_gi_size;
uniform ivec2 u_padded;
uniform ivec2 u_pad;
uniform float u_out_k;
uniform float u_log_r;
uniform float u_floor_lo;       // the albedo floor in encoded albedo, 2 floor - 1

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);  // row top first
    if (t.x >= u_gi_size.x || t.y >= u_gi_size.y) return;
    int plane = u_padded.x * u_padded.y;
    int at = (t.y + u_pad.y) * u_padded.x + t.x + u_pad.x;
    vec3 y = vec3(raw[at], raw[at + plane], raw[at + 2 * plane]);
    vec3 ay = abs(y);
    vec3 c = (exp(ay * u_log_r) - 1.0) * (y / max(ay, vec3(1e-30))) * u_out_k;
#if !defined FULL
    int base = (t.y * u_gi_size.x + t.x) * IN_CHANNELS;
#if defined DIVIDE_ALBEDO
    vec3 albedo = vec3(data[base + IN_ALBEDO], data[base + IN_ALBEDO + 1], data[base + IN_ALBEDO + 2]);
    albedo = mix(albedo, vec3(0.0), isnan(albedo));
    c *= max(clamp(albedo * 2.0 - 1.0, -1.0, 1.0), vec3(u_floor_lo)) + 1.0;
#endif
    c += vec3(data[base + IN_DIRECT], data[base + IN_DIRECT + 1], data[base + IN_DIRECT + 2]);
#endif
    for (int k = 0; k < 3; ++k)  // a NaN kept (a comparison with NaN may read true here)
        if (!isnan(c[k]) && c[k] < 0.0) c[k] = 0.0;
    imageStore(u_radiance, t, vec4(c, 1.0));
}

#endif
