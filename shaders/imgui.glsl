// The viewer's panel: imgui draw lists (2D positions in display pixels, font-atlas uv, vertex colour).
#if defined VERTEX_SHADER

in vec2 in_position;
in vec2 in_uv;
in vec4 in_color;

uniform mat4 m_proj;     // display pixels (origin top left, y down) to clip space

out vec2 v_uv;
out vec4 v_color;

void main() {
    v_uv = in_uv;
    v_color = in_color;
    gl_Position = m_proj * vec4(in_position, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

in vec2 v_uv;
in vec4 v_color;

uniform sampler2D u_texture;

out vec4 out_color;

void main() {
    out_color = v_color * texture(u_texture, v_uv);
}

#endif
