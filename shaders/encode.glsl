// The network's encoded input of one padded texel, as the exported graph computes it (diviewer.train.graph,
// diviewer.contract.lean.LeanModel.encode): NaN made 0 and infinite depth 0 (no geometry), then depth / depth_scale
// (-1 off the surfaces), the normal, 2 albedo - 1, the direct light exposed by u_in_k (the frame's light scale
// folded in) as sign(c) log(1 + |c|) / log(1 + radiance_max); with WORLD the world position and normal from the
// padded camera (diviewer.scene.camera.camera_params); with LIGHTS the lights' parameters over the surfaces.
// Reads the raw inputs pack.glsl wrote (binding 0, NHWC rows top first, IN_* offsets) over the network's padded
// input (u_padded, the frame at u_pad, edge texels repeated as the runtime pads them) and writes float32 NCHW into
// binding 1, planes of u_padded.x * u_padded.y.
#if defined COMPUTE_SHADER

layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 0) readonly buffer Packed { float data[]; };
layout(std430, binding = 1) writeonly buffer Encoded { float enc[]; };
uniform ivec2 u_size;           // the GI size (the raw inputs')
uniform ivec2 u_padded;         // the network's input size (the GI size padded to its stride)
uniform ivec2 u_pad;            // where the frame starts in it (left, top)
uniform float u_in_k;           // exposure / light scale (0 for no light)
uniform float u_depth_inv;      // 1 / depth_scale
uniform float u_radiance_max;
uniform float u_log_r;          // log(1 + radiance_max)
#if defined WORLD
uniform float u_camera[20];     // the padded frame's camera
uniform vec3 u_world_center;
uniform vec3 u_world_inv_half;
#endif
#if defined LIGHTS
uniform float u_light[3 * LIGHTS];
#endif

const float LEAN_TINY = 1e-30;  // x / max(|x|, TINY): a sign, as the graph's
const float LEAN_HUGE = 1e38;   // clip(d HUGE, 0, 1): 1 on any surface, as the graph's

void put(int plane, int at, float v) { enc[plane * u_padded.x * u_padded.y + at] = v; }

vec3 nan_to_zero(vec3 v) { return mix(v, vec3(0.0), isnan(v)); }

void encode(ivec2 P, float z, vec3 n, vec3 a, vec3 d) {
    int at = P.y * u_padded.x + P.x;
    z = (isnan(z) || isinf(z)) ? 0.0 : z;
    n = nan_to_zero(n);
    a = nan_to_zero(a);
    d = nan_to_zero(d);
    float dz = z * u_depth_inv;
    put(0, at, clamp(dz, 0.0, 1.0) - clamp(1.0 - dz * LEAN_HUGE, 0.0, 1.0));
    vec3 en = clamp(n, -1.0, 1.0), ea = clamp(a * 2.0 - 1.0, -1.0, 1.0);
    vec3 c = clamp(d * u_in_k, -u_radiance_max, u_radiance_max);
    vec3 ac = abs(c);
    vec3 ed = log(ac + 1.0) * (c / max(ac * u_log_r, LEAN_TINY * u_log_r));
    for (int k = 0; k < 3; ++k) {
        put(1 + k, at, en[k]);
        put(4 + k, at, ea[k]);
        put(7 + k, at, ed[k]);
    }
    float geo = clamp(z * LEAN_HUGE, 0.0, 1.0);
#if defined WORLD
    float col = min(max(float(P.x), u_camera[16]), u_camera[17]) + 0.5;
    float row = min(max(float(P.y), u_camera[18]), u_camera[19]) + 0.5;
    vec3 view = vec3(z * (u_camera[12] * col + u_camera[13]), z * (u_camera[14] * row + u_camera[15]), -z);
    for (int k = 0; k < 3; ++k) {
        float pos = u_camera[3 * k] * view.x + u_camera[3 * k + 1] * view.y + u_camera[3 * k + 2] * view.z
            + u_camera[9 + k];
        float wn = u_camera[3 * k] * en.x + u_camera[3 * k + 1] * en.y + u_camera[3 * k + 2] * en.z;
        put(10 + k, at, clamp((pos - u_world_center[k]) * u_world_inv_half[k], -1.0, 1.0) * geo);
        put(13 + k, at, clamp(wn, -1.0, 1.0) * geo);
    }
#endif
#if defined LIGHTS
    for (int k = 0; k < 3 * LIGHTS; ++k) put(16 + k, at, u_light[k] * geo);
#endif
}

void main() {
    ivec2 P = ivec2(gl_GlobalInvocationID.xy);  // padded texel, row top first
    if (P.x >= u_padded.x || P.y >= u_padded.y) return;
    ivec2 f = clamp(P - u_pad, ivec2(0), u_size - 1);  // the frame's texel it repeats, row top first
    int base = (f.y * u_size.x + f.x) * IN_CHANNELS;
    vec3 n = vec3(data[base + IN_NORMAL], data[base + IN_NORMAL + 1], data[base + IN_NORMAL + 2]);
    vec3 a = vec3(data[base + IN_ALBEDO], data[base + IN_ALBEDO + 1], data[base + IN_ALBEDO + 2]);
    vec3 d = vec3(data[base + IN_DIRECT], data[base + IN_DIRECT + 1], data[base + IN_DIRECT + 2]);
    encode(P, data[base + IN_DEPTH], n, a, d);
}

#endif
