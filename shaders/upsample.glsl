// GI below frame resolution: the frame's exact direct light plus the GI pass's indirect light (its output
// minus the direct light it was given), bilinearly upsampled. Indirect light is smooth, so it is the part
// that survives the lower resolution; edges and shadows keep the frame's own direct light.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

in vec2 v_uv;

uniform sampler2D u_direct;     // frame resolution, rows bottom first (the renderer's)
uniform sampler2D u_indirect;   // GI resolution, rows top first (the model's), LINEAR filter

out vec4 out_color;

void main() {
    vec3 direct = texelFetch(u_direct, ivec2(gl_FragCoord.xy), 0).rgb;
    vec3 indirect = texture(u_indirect, vec2(v_uv.x, 1.0 - v_uv.y)).rgb;
    out_color = vec4(direct + indirect, 1.0);
}

#endif
