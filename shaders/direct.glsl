// Direct light, deferred: one additive pass per light (Lambert, shadow-mapped with PCF), plus one
// EMISSION pass. Radiance of a diffuse surface: albedo / pi * E * cos(theta) for a directional light
// of irradiance E; albedo / pi * I * cos(theta) / r^2 for a point light of intensity I (Mitsuba's).
// With SHADOW_LOOKUP defined (and no stage macro), only the uniforms and the functions are compiled:
// the VXGI injection (vxgi_inject.glsl) includes this file so that both shadow the same way, and
// direct_inline.glsl so that the neural pass computes a pixel's direct light exactly as this pass does.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER || defined SHADOW_LOOKUP

const float PI = 3.14159265358979;

uniform mat4 m_inv_view;          // camera to world
uniform vec2 u_tan_half_fov;      // (tan(fov_y / 2) * aspect, tan(fov_y / 2))
uniform vec2 u_jitter;            // the G-buffer's jitter (pixels): pixel centre c shows what lies at c - u_jitter

uniform vec3 u_light_color;       // colour * irradiance (directional) or colour * intensity (point)
uniform vec3 u_light_dir;         // directional: the direction the light travels, world space
uniform vec3 u_light_pos;         // point: position, world space
uniform bool u_shadows;
uniform int u_pcf_radius;         // PCF kernel is (2r+1)^2 taps
uniform float u_bias;             // constant bias, in shadow-map texels
uniform float u_slope_bias;       // slope-scaled bias, in texels per unit tan(theta)
uniform float u_normal_offset;    // offset along the normal, in shadow-map texels

#if defined DIRECTIONAL
uniform sampler2DShadow u_shadow_map;
uniform mat4 m_light;             // world -> light clip (orthographic)
uniform float u_texel_world;      // world size of one shadow texel
uniform float u_depth_range;      // light-space depth range (far - near), world units
#elif defined POINT_LIGHT
uniform sampler2D u_shadow_atlas; // 3x2 tiles of distances to the light
uniform mat4 m_faces[6];          // world -> clip of each cube face
uniform float u_face_size;        // tile size in texels
#endif

#if !defined SHADOW_LOOKUP
out vec4 out_color;
#endif

#if defined DIRECTIONAL
// Percentage-closer filtering: the mean of (2r+1)^2 bilinear depth comparisons at whole-texel offsets
// around uv. Those taps cover (2r+2)^2 texels, each weighted by wx(i) * wy(j), with wx = 1 - f.x at
// the block's left column, f.x at its right one and 1 between: the same sum as the taps', from
// (r+1)^2 textureGather calls of four comparisons each instead of (2r+1)^2 filtered lookups.
float pcf(vec2 uv, float ref) {
    int r = u_pcf_radius;
    vec2 size = vec2(textureSize(u_shadow_map, 0));
    vec2 st = uv * size - 0.5;
    vec2 base = floor(st);
    vec2 f = st - base;
    float sum = 0.0;
    for (int j = -r; j <= r + 1; j += 2)
        for (int i = -r; i <= r + 1; i += 2) {
            // texels (i, j), (i+1, j), (i, j+1), (i+1, j+1) come back as w, z, x, y
            vec4 g = textureGather(u_shadow_map, (base + vec2(i, j) + 1.0) / size, ref);
            vec2 wx = vec2(i == -r ? 1.0 - f.x : 1.0, i + 1 == r + 1 ? f.x : 1.0);
            vec2 wy = vec2(j == -r ? 1.0 - f.y : 1.0, j + 1 == r + 1 ? f.y : 1.0);
            sum += dot(g, vec4(wx.x * wy.y, wx.y * wy.y, wx.y * wy.x, wx.x * wy.x));
        }
    return sum / float((2 * r + 1) * (2 * r + 1));
}

float visibility(vec3 p, vec3 n, float cos_t) {
    float tan_t = sqrt(max(1.0 - cos_t * cos_t, 0.0)) / max(cos_t, 1e-3);
    vec3 q = p + n * (u_normal_offset * u_texel_world);
    vec4 c = m_light * vec4(q, 1.0);
    vec3 s = c.xyz * 0.5 + 0.5;
    if (any(lessThan(s.xy, vec2(0.0))) || any(greaterThan(s.xy, vec2(1.0))) || s.z > 1.0) return 1.0;
    float bias = (u_bias + u_slope_bias * min(tan_t, 10.0)) * u_texel_world / u_depth_range;
    return pcf(s.xy, s.z - bias);
}
#elif defined POINT_LIGHT
float visibility(vec3 p, vec3 n, float cos_t) {
    vec3 d = p - u_light_pos;
    float dist = length(d);
    vec3 a = abs(d);
    int face = (a.x >= a.y && a.x >= a.z) ? (d.x > 0.0 ? 0 : 1) : (a.y >= a.z ? (d.y > 0.0 ? 2 : 3) : (d.z > 0.0 ? 4 : 5));
    // world size of a texel at this distance for a 90-degree face
    float texel_world = 2.0 * dist / u_face_size;
    float tan_t = sqrt(max(1.0 - cos_t * cos_t, 0.0)) / max(cos_t, 1e-3);
    vec3 q = p + n * (u_normal_offset * texel_world);
    vec4 c = m_faces[face] * vec4(q, 1.0);
    vec2 uv = c.xy / c.w * 0.5 + 0.5;
    float bias = (u_bias + u_slope_bias * min(tan_t, 10.0)) * texel_world;
    float qd = length(q - u_light_pos) - bias;
    vec2 tile = vec2(face % 3, face / 3);
    vec2 atlas = vec2(3.0, 2.0) * u_face_size;
    float sum = 0.0;
    int taps = 0;
    for (int y = -u_pcf_radius; y <= u_pcf_radius; ++y)
        for (int x = -u_pcf_radius; x <= u_pcf_radius; ++x) {
            vec2 t = clamp(uv * u_face_size + vec2(x, y), vec2(0.5), vec2(u_face_size - 0.5));
            float stored = texture(u_shadow_atlas, (tile * u_face_size + t) / atlas).r;
            sum += qd <= stored ? 1.0 : 0.0;
            ++taps;
        }
    return sum / float(taps);
}
#endif

// Direction to the light and irradiance at p, facing the light (Mitsuba's radiometry: E for a
// directional light, I / r^2 for a point light); shared with the VXGI injection.
#if defined DIRECTIONAL || defined POINT_LIGHT
void light_at(vec3 p, out vec3 l, out vec3 e) {
#if defined DIRECTIONAL
    l = -normalize(u_light_dir);
    e = u_light_color;
#else
    vec3 to_light = u_light_pos - p;
    float r2 = max(dot(to_light, to_light), 1e-12);
    l = to_light * inversesqrt(r2);
    e = u_light_color / r2;
#endif
}
#endif

// One light's term at a pixel (centre ``pixel`` of an image of ``size``) from its G-buffer values:
// linear depth (> 0: a surface), view-space normal, albedo. Zero where the surface faces away.
#if defined DIRECTIONAL || defined POINT_LIGHT
vec3 light_term(vec2 pixel, vec2 size, float depth, vec3 n_view, vec3 albedo) {
    vec2 ndc = ((pixel - u_jitter) / size) * 2.0 - 1.0;
    vec3 p_view = depth * vec3(ndc * u_tan_half_fov, -1.0);
    vec3 p = (m_inv_view * vec4(p_view, 1.0)).xyz;
    vec3 n = normalize(mat3(m_inv_view) * n_view);
    vec3 l, e;
    light_at(p, l, e);
    float cos_t = dot(n, l);
    if (cos_t <= 0.0) return vec3(0.0);
    float v = u_shadows ? visibility(p, n, cos_t) : 1.0;
    return albedo / PI * e * (cos_t * v);
}
#endif

#if !defined SHADOW_LOOKUP
in vec2 v_uv;
uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform sampler2D u_albedo;
uniform sampler2D u_emission;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    float depth = texelFetch(u_depth, px, 0).r;
    if (depth <= 0.0) discard;    // background: no surface
#if defined EMISSION
    out_color = vec4(texelFetch(u_emission, px, 0).rgb, 1.0);
#else
    out_color = vec4(light_term(gl_FragCoord.xy, vec2(textureSize(u_depth, 0)), depth,
                                texelFetch(u_normal, px, 0).xyz, texelFetch(u_albedo, px, 0).rgb), 1.0);
#endif
}
#endif  // !SHADOW_LOOKUP

#endif
