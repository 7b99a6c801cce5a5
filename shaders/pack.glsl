// Packs the G-buffer into the neural model's input: float32 NHWC, rows top first, in one storage
// buffer, so the CPU reads it once and reshuffles nothing. The G-buffer is at the window's resolution
// (u_src_size), the model's input at the GI resolution (u_size): each GI texel takes the full-resolution
// pixel nearest its centre (what a render at the GI resolution samples, as the training captures did),
// or with AREA defined the mean of the pixels whose centres fall in its footprint for normal, albedo and
// direct light (depth stays the nearest pixel's: a mean of two surfaces' depths is no surface's); with
// AREA_DIRECT that mean for the direct light alone (models with direct_samples > 1 on their card). The channel layout is not written here:
// gl/neural.py injects it from diviewer.contract.encoding.INPUT_CHANNELS as defines (IN_CHANNELS, the total,
// IN_<NAME>, where each buffer starts, and IN_<NAME>_N, its component count, checked below). The direct
// light is read from the direct pass's target or, with INLINE_DIRECT, computed (direct_inline.glsl).
// For a model's lean path (diviewer.contract.lean) encode.glsl then encodes what it wrote.
#if defined COMPUTE_SHADER

#if !defined IN_CHANNELS || !defined IN_DEPTH || !defined IN_NORMAL || !defined IN_ALBEDO || !defined IN_DIRECT
#error "pack.glsl needs the channel layout defines from diviewer.gl.neural"
#endif
#if IN_DEPTH_N != 1 || IN_NORMAL_N != 3 || IN_ALBEDO_N != 3 || IN_DIRECT_N != 3
#error "the encoding's channel counts differ from what pack.glsl writes (1 depth, 3 normal, albedo, direct)"
#endif

layout(local_size_x = 8, local_size_y = 8) in;

uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform sampler2D u_albedo;
uniform ivec2 u_size;       // GI resolution (the packed image's)
uniform ivec2 u_src_size;   // the G-buffer's resolution

layout(std430, binding = 0) writeonly buffer Packed { float data[]; };

#include "direct_inline.glsl"

// The GI texel p's buffers (p.y bottom first).
void gather(ivec2 p, out float z, out vec3 n, out vec3 a, out vec3 d) {
    vec2 scale = vec2(u_src_size) / vec2(u_size);
    ivec2 q = clamp(ivec2((vec2(p) + 0.5) * scale), ivec2(0), u_src_size - 1);
    vec2 src = vec2(u_src_size);
    z = texelFetch(u_depth, q, 0).r;
    n = texelFetch(u_normal, q, 0).xyz;
    a = texelFetch(u_albedo, q, 0).rgb;
    d = direct_at(q, src, z, n, a);
#if defined AREA || defined AREA_DIRECT
    // Pixels whose centres lie in [p, p + 1) * scale; none when the GI is finer than the G-buffer.
    ivec2 lo = ivec2(ceil(vec2(p) * scale - 0.5));
    ivec2 hi = min(ivec2(ceil((vec2(p) + 1.0) * scale - 0.5)), u_src_size);
    if (all(greaterThan(hi, lo))) {
        vec3 sn = vec3(0.0), sa = vec3(0.0), sd = vec3(0.0);
        for (int y = lo.y; y < hi.y; ++y)
            for (int x = lo.x; x < hi.x; ++x) {
                ivec2 o = ivec2(x, y);
                vec3 no = texelFetch(u_normal, o, 0).xyz, ao = texelFetch(u_albedo, o, 0).rgb;
                sn += no;
                sa += ao;
                sd += direct_at(o, src, texelFetch(u_depth, o, 0).r, no, ao);
            }
        float count = float((hi.x - lo.x) * (hi.y - lo.y));
#if defined AREA
        n = dot(sn, sn) > 0.0 ? normalize(sn) : vec3(0.0);
        a = sa / count;
#endif
        // AREA_DIRECT alone: the direct light over the texel's area (a model of diviewer.gl.area's light, trained
        // on it), the surface at its centre
        d = sd / count;
    }
#endif
}

void put_raw(int base, float z, vec3 n, vec3 a, vec3 d) {
    data[base + IN_DEPTH] = z;
    data[base + IN_NORMAL] = n.x; data[base + IN_NORMAL + 1] = n.y; data[base + IN_NORMAL + 2] = n.z;
    data[base + IN_ALBEDO] = a.r; data[base + IN_ALBEDO + 1] = a.g; data[base + IN_ALBEDO + 2] = a.b;
    data[base + IN_DIRECT] = d.r; data[base + IN_DIRECT + 1] = d.g; data[base + IN_DIRECT + 2] = d.b;
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= u_size.x || p.y >= u_size.y) return;
    float z; vec3 n, a, d;
    gather(p, z, n, a, d);
    put_raw(((u_size.y - 1 - p.y) * u_size.x + p.x) * IN_CHANNELS, z, n, a, d);
}

#endif
