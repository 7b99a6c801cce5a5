// VXGI composite: the image is direct + albedo * indirect (direct already holds the emission seen),
// and the indirect part alone, albedo * indirect, comparable with the path tracer's full - direct.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

uniform sampler2D u_direct;
uniform sampler2D u_albedo;
uniform sampler2D u_gi;           // full resolution (indirect, AO)

layout(location = 0) out vec4 out_vxgi;
layout(location = 1) out vec4 out_indirect;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 bounce = texelFetch(u_albedo, px, 0).rgb * texelFetch(u_gi, px, 0).rgb;
    out_vxgi = vec4(texelFetch(u_direct, px, 0).rgb + bounce, 1.0);
    out_indirect = vec4(bounce, 1.0);
}

#endif
