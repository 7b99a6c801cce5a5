// Shadow maps. Directional: depth only, orthographic. POINT_LIGHT: distance to the light in a colour
// attachment, one tile of a 3x2 atlas per cube face (the face is chosen by the viewport).
#if defined VERTEX_SHADER

in vec3 in_position;

uniform mat4 m_light;    // light projection * light view
uniform mat4 m_model;

out vec3 v_world;

void main() {
    vec4 w = m_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    gl_Position = m_light * w;
}

#elif defined FRAGMENT_SHADER

in vec3 v_world;

#if defined POINT_LIGHT
uniform vec3 u_light_pos;
layout(location = 0) out float out_distance;
#endif

void main() {
#if defined POINT_LIGHT
    out_distance = length(v_world - u_light_pos);
#endif
}

#endif
