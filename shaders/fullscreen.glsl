// Shared by the screen-space passes: one triangle that covers the viewport; v_uv has (0,0) at the
// bottom-left pixel corner, as GL textures do.
#if defined VERTEX_SHADER
out vec2 v_uv;
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    v_uv = p * 0.5 + 0.5;
    gl_Position = vec4(p, 0.0, 1.0);
}
#endif
