// G-buffer: linear view-space depth, view-space normal (facing the camera), albedo, emission; with VELOCITY (the
// velocity target's location) also the motion vectors (diviewer/gl/motion.py).
#if defined VERTEX_SHADER

in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;

uniform mat4 m_proj;
uniform mat4 m_view;
uniform mat4 m_model;
uniform mat3 m_normal;   // inverse transpose of (m_view * m_model), upper 3x3

out float v_depth;       // linear view-space depth (-z)
out vec3 v_normal;       // view space
out vec2 v_uv;
#if defined VELOCITY
uniform mat4 m_proj_unjittered;  // this frame's projection without the jitter
uniform mat4 m_prev_model;       // the previous frame's, and its view and unjittered projection
uniform mat4 m_prev_view;
uniform mat4 m_prev_proj;
out vec4 v_clip;                 // this frame's unjittered clip position
out vec4 v_prev_clip;            // the previous frame's
out float v_prev_depth;          // the previous frame's linear view depth
#endif

void main() {
    // Two matrix-vector products, not a matrix-matrix product per vertex (Sponza draws ~250k triangles).
    vec4 p = m_view * (m_model * vec4(in_position, 1.0));
    v_depth = -p.z;
    v_normal = m_normal * in_normal;
    v_uv = in_uv;
    gl_Position = m_proj * p;
#if defined VELOCITY
    vec4 q = m_prev_view * (m_prev_model * vec4(in_position, 1.0));
    v_clip = m_proj_unjittered * p;
    v_prev_clip = m_prev_proj * q;
    v_prev_depth = -q.z;
#endif
}

#elif defined FRAGMENT_SHADER

in float v_depth;
in vec3 v_normal;
in vec2 v_uv;
#if defined VELOCITY
in vec4 v_clip;
in vec4 v_prev_clip;
in float v_prev_depth;
#endif

uniform vec3 u_albedo;
uniform vec3 u_emission;
uniform bool u_has_texture;
uniform sampler2D u_albedo_map;  // linear RGB, alpha = cut-out mask (1 where the material has none)
uniform bool u_has_emission_map;
uniform sampler2D u_emission_map;  // linear RGB emission texture; u_emission multiplies it
#if defined ALPHA_TEST
uniform float u_alpha_cutoff;
// The cut-out test reads the nearest texel of the full-resolution mask, as the path tracer does
// (diviewer/reference/mitsuba.py): the same texel decides in both, at every distance.
float mask_alpha(sampler2D tex, vec2 uv) {
    ivec2 size = textureSize(tex, 0);
    ivec2 texel = clamp(ivec2(floor(fract(uv) * vec2(size))), ivec2(0), size - ivec2(1));
    return texelFetch(tex, texel, 0).a;
}
#endif

layout(location = 0) out float out_depth;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_albedo;
#if !defined VELOCITY || VELOCITY == 4
layout(location = 3) out vec4 out_emission;
#endif
#if defined VELOCITY
// rg: previous minus current texture coordinates (unjittered); b: previous minus current linear depth; a: 1.
layout(location = VELOCITY) out vec4 out_velocity;
#endif

void main() {
    vec3 n = normalize(v_normal);
    // Surfaces are two-sided: a back face is lit and shaded as the side the camera sees.
    if (!gl_FrontFacing) n = -n;
    vec4 texel = u_has_texture ? texture(u_albedo_map, v_uv) : vec4(1.0);
#if defined ALPHA_TEST
    if (mask_alpha(u_albedo_map, v_uv) < u_alpha_cutoff) discard;  // glTF alphaMode MASK: the surface is not there
#endif
    vec3 albedo = u_albedo * texel.rgb;
    out_depth = v_depth;
    out_normal = vec4(n, 1.0);
    out_albedo = vec4(albedo, 1.0);
#if !defined VELOCITY || VELOCITY == 4
    vec3 emission = u_emission;
    if (u_has_emission_map) emission *= texture(u_emission_map, v_uv).rgb;
    out_emission = vec4(emission, 1.0);
#endif
#if defined VELOCITY
    // A point behind the previous camera had no place on its screen: an offset far outside it.
    vec2 moved = v_prev_clip.w > 0.0 ? (v_prev_clip.xy / v_prev_clip.w - v_clip.xy / v_clip.w) * 0.5 : vec2(1e4);
    out_velocity = vec4(moved, v_prev_depth - v_depth, 1.0);
#endif
}

#endif
