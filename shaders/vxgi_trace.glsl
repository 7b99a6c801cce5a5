// VXGI diffuse cone tracing from the G-buffer, one pixel of the trace resolution per fragment (a
// lower trace resolution reads the G-buffer at the centre of its block); the cones are vxgi_cone.glsl's.
// Out: (indirect, AO) with indirect = E / pi (the cosine-weighted mean incoming radiance, so the
// outgoing indirect radiance is albedo * indirect) and AO the unoccluded fraction within u_ao_dist;
// and the (view normal, depth) of the pixel traced, for the depth/normal-aware upsampling.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

#include "vxgi_cone.glsl"

uniform sampler2D u_depth;
uniform sampler2D u_normal;

uniform mat4 m_inv_view;          // camera to world
uniform vec2 u_tan_half_fov;      // (tan(fov_y / 2) * aspect, tan(fov_y / 2))
uniform int u_scale;              // full-resolution pixels per trace pixel (per side)

layout(location = 0) out vec4 out_gi;
layout(location = 1) out vec4 out_geom;

void main() {
    ivec2 size = textureSize(u_depth, 0);
    ivec2 px = min(ivec2(gl_FragCoord.xy) * u_scale + u_scale / 2, size - 1);
    float depth = texelFetch(u_depth, px, 0).r;
    vec3 n_view = texelFetch(u_normal, px, 0).xyz;
    out_geom = vec4(n_view, depth);
    if (depth <= 0.0) { out_gi = vec4(0.0, 0.0, 0.0, 1.0); return; }   // background
    vec2 ndc = ((vec2(px) + 0.5) / vec2(size)) * 2.0 - 1.0;
    vec3 p = (m_inv_view * vec4(depth * vec3(ndc * u_tan_half_fov, -1.0), 1.0)).xyz;
    vec3 n = normalize(mat3(m_inv_view) * n_view);
    vec4 g = gather(p, n);
    out_gi = vec4(g.rgb, 1.0 - g.a);
}

#endif
