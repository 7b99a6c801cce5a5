// Temporal upsampling (Karis 2014; AMD FSR 2): the radiance of a jittered frame at the shading resolution,
// accumulated at the window's resolution into a history reprojected by the G-buffer's motion vectors (each object's
// motion and the camera's; where there are none, by the depth and the camera's motion), the history clamped to the
// current frame's 3x3 neighbourhood (YCoCg box) and dropped where the reprojected depth lies outside the
// neighbourhood's depths (disocclusion).
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

in vec2 v_uv;

uniform sampler2D u_current;   // this frame's radiance, shading resolution, jittered (nearest)
uniform sampler2D u_depth;     // this frame's linear view depth (-z; 0: sky), shading resolution, jittered
uniform sampler2D u_history;   // rgb: accumulated radiance, a: its weight; window resolution (linear)
uniform sampler2D u_history_depth;  // the history's linear view depth (nearest)
uniform sampler2D u_velocity;  // the G-buffer's motion vectors (diviewer/gl/motion.py), shading resolution, jittered
uniform bool u_has_velocity;
uniform vec2 u_jitter;         // this frame's jitter, shading pixels (pixel centre c shows what lies at c - jitter)
uniform vec2 u_inv_focal;      // 1 / proj[0][0], 1 / proj[1][1]: view-space x, y per unit depth at NDC 1
uniform mat4 m_reproj;         // this frame's view space -> the history's clip space
uniform mat4 m_prev_view;      // this frame's view space -> the history's view space
uniform bool u_has_history;
uniform float u_max_weight;    // cap of the history's weight (units: one sample at a pixel's centre)
uniform float u_sigma;         // the current sample's weight: a Gaussian of its distance, in window pixels
uniform float u_gamma;          // variance clipping: the colour box is the mean +- this many standard deviations
uniform float u_depth_tolerance;  // relative depth mismatch that rejects the history

layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_depth;

vec3 to_ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}

vec3 from_ycocg(vec3 c) {
    return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z);
}

void main() {
    ivec2 size = textureSize(u_current, 0);
    vec2 out_size = vec2(textureSize(u_history, 0));
    // The sample nearest to this window pixel: render pixel i holds what lies at i + 0.5 - jitter.
    vec2 p = v_uv * vec2(size);
    ivec2 i = clamp(ivec2(floor(p + u_jitter)), ivec2(0), size - 1);
    vec2 d = (p - (vec2(i) + 0.5 - u_jitter)) * out_size / vec2(size);  // window pixels
    vec3 cur = texelFetch(u_current, i, 0).rgb;
    float z = texelFetch(u_depth, i, 0).r;
    float w = exp(-0.5 * dot(d, d) / (u_sigma * u_sigma));
    vec3 lo = vec3(1e30), hi = vec3(-1e30), m1 = vec3(0.0), m2 = vec3(0.0);
    float z_lo = 1e30, z_hi = 0.0, z_front = 1e30;
    ivec2 front = i;  // the neighbourhood's nearest surface
    for (int y = -1; y <= 1; ++y) {
        for (int x = -1; x <= 1; ++x) {
            ivec2 q = clamp(i + ivec2(x, y), ivec2(0), size - 1);
            vec3 c = to_ycocg(texelFetch(u_current, q, 0).rgb);
            lo = min(lo, c);
            hi = max(hi, c);
            m1 += c;
            m2 += c * c;
            float zq = texelFetch(u_depth, q, 0).r;
            if (zq > 0.0 && zq < z_front) {
                front = q;
                z_front = zq;
            }
            z_lo = min(z_lo, zq);
            z_hi = max(z_hi, zq);
        }
    }
    // Variance clipping (Salvi 2016): the box narrowed to the mean +- gamma standard deviations.
    m1 /= 9.0;
    vec3 sd = sqrt(max(m2 / 9.0 - m1 * m1, 0.0));
    lo = max(lo, m1 - u_gamma * sd);
    hi = min(hi, m1 + u_gamma * sd);
    // This pixel's point (sky: its direction) in view space, then in the history's clip and view spaces.
    vec2 ndc = v_uv * 2.0 - 1.0;
    vec4 pv = z > 0.0 ? vec4(ndc * u_inv_focal * z, -z, 1.0) : vec4(ndc * u_inv_focal, -1.0, 0.0);
    vec4 clip = m_reproj * pv;
    vec2 prev_uv = clip.xy / clip.w * 0.5 + 0.5;
    bool ahead = clip.w > 0.0;
    // This point's change of depth since the history (previous - current).
    float change = z > 0.0 ? -(m_prev_view * pv).z - z : 0.0;
    // A surface is reprojected by the motion vector of the nearest surface of its 3x3 neighbourhood (Karis 2014): the
    // pixels along a moving object's edge follow the object and keep its history, clamped to their neighbourhood.
    if (u_has_velocity && z > 0.0) {
        vec4 mv = texelFetch(u_velocity, front, 0);
        prev_uv = v_uv + mv.xy;
        change = mv.z;
        ahead = true;
    }
    float weight = 0.0;
    vec3 hist = cur;
    if (u_has_history && ahead && all(greaterThanEqual(prev_uv, vec2(0.0)))
            && all(lessThanEqual(prev_uv, vec2(1.0)))) {
        vec4 h = texture(u_history, prev_uv);
        float hz = texture(u_history_depth, prev_uv).r;
        // Disoccluded where the history's depth, moved back by this point's own depth change, lies outside the
        // depths of the current 3x3 neighbourhood: an edge's samples alternate between its two sides (the nearest
        // sample changes with the jitter), which is not a disocclusion.
        float back = hz - change;
        bool same = back >= z_lo * (1.0 - u_depth_tolerance) - 1e-6 && back <= z_hi * (1.0 + u_depth_tolerance) + 1e-6;
        if (same) {
            hist = from_ycocg(clamp(to_ycocg(h.rgb), lo, hi));
            weight = min(h.a, u_max_weight);
        }
    }
    vec3 c = weight + w > 1e-6 ? (hist * weight + cur * w) / (weight + w) : cur;
    out_color = vec4(c, weight + w);
    out_depth = z;
}

#endif
