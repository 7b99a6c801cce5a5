// Shadow maps. Directional: depth only, orthographic. POINT_LIGHT: distance to the light in a colour
// attachment, one tile of a 3x2 atlas per cube face (the face is chosen by the viewport).
// ALPHA_TEST: alpha-masked materials cast shadows only where the G-buffer keeps them.
#if defined VERTEX_SHADER

in vec3 in_position;

uniform mat4 m_light;    // light projection * light view
uniform mat4 m_model;

out vec3 v_world;
#if defined ALPHA_TEST
in vec2 in_uv;
out vec2 v_uv;
#endif

void main() {
    vec4 w = m_model * vec4(in_position, 1.0);
    v_world = w.xyz;
#if defined ALPHA_TEST
    v_uv = in_uv;
#endif
    gl_Position = m_light * w;
}

#elif defined FRAGMENT_SHADER

in vec3 v_world;
#if defined ALPHA_TEST
in vec2 v_uv;
uniform sampler2D u_albedo_map;
uniform float u_alpha_cutoff;
// The cut-out test reads the nearest texel of the full-resolution mask, as the path tracer does
// (diviewer/reference/mitsuba.py): the same texel decides in both, at every distance.
float mask_alpha(sampler2D tex, vec2 uv) {
    ivec2 size = textureSize(tex, 0);
    ivec2 texel = clamp(ivec2(floor(fract(uv) * vec2(size))), ivec2(0), size - ivec2(1));
    return texelFetch(tex, texel, 0).a;
}
#endif

#if defined POINT_LIGHT
uniform vec3 u_light_pos;
layout(location = 0) out float out_distance;
#endif

void main() {
#if defined ALPHA_TEST
    if (mask_alpha(u_albedo_map, v_uv) < u_alpha_cutoff) discard;
#endif
#if defined POINT_LIGHT
    out_distance = length(v_world - u_light_pos);
#endif
}

#endif
