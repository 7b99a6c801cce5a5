// Once per frame at the GI resolution, before the upsample: each GI texel's guide (depth, normal) and its
// demodulated indirect light, from the inputs the network read (the packed storage buffer, rows top
// first, IN_* offsets as pack.glsl) and its output. Done here once per texel rather than in
// upsample.glsl once per pixel and neighbour: the full-resolution pass then reads two textures.
//
// Indirect light = the network's output minus the direct light it was given (for an `indirect` model
// that is exactly what its graph added; for a `full` model it also carries the network's own error in
// the direct light), divided by the texel's albedo (irradiance varies slowly, albedo does not:
// textures and material edges stay sharp when upsample.glsl multiplies by each pixel's own albedo).
#if defined COMPUTE_SHADER

layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 0) readonly buffer Packed { float data[]; };
uniform sampler2D u_output;     // the network's output, rows top first
uniform ivec2 u_gi_size;
layout(rgba32f, binding = 0) writeonly uniform image2D u_irradiance_depth;  // rgb: indirect / albedo, a: depth
layout(rgba32f, binding = 1) writeonly uniform image2D u_guide_normal;      // xyz: normal

const float ALBEDO_FLOOR = 0.02;  // below it the demodulated irradiance is mostly the network's noise

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (t.x >= u_gi_size.x || t.y >= u_gi_size.y) return;
    int base = ((u_gi_size.y - 1 - t.y) * u_gi_size.x + t.x) * IN_CHANNELS;
    vec3 normal = vec3(data[base + IN_NORMAL], data[base + IN_NORMAL + 1], data[base + IN_NORMAL + 2]);
    vec3 albedo = vec3(data[base + IN_ALBEDO], data[base + IN_ALBEDO + 1], data[base + IN_ALBEDO + 2]);
    vec3 direct = vec3(data[base + IN_DIRECT], data[base + IN_DIRECT + 1], data[base + IN_DIRECT + 2]);
    vec3 out_rgb = texelFetch(u_output, ivec2(t.x, u_gi_size.y - 1 - t.y), 0).rgb;
    vec3 irradiance = (out_rgb - direct) / max(albedo, vec3(ALBEDO_FLOOR));
    imageStore(u_irradiance_depth, t, vec4(irradiance, data[base + IN_DEPTH]));
    imageStore(u_guide_normal, t, vec4(normal, 0.0));
}

#endif
