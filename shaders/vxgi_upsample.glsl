// VXGI joint bilateral upsampling: a full-resolution pixel takes the 4 nearest trace pixels, weighted
// bilinearly and by how alike their depth and normal are to its own, so indirect light does not bleed
// across depth or normal edges; where none is alike, the one of nearest depth.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

uniform sampler2D u_depth;        // full resolution
uniform sampler2D u_normal;       // full resolution, view space
uniform sampler2D u_gi;           // trace resolution: (indirect, AO)
uniform sampler2D u_geom;         // trace resolution: (view normal, depth) of the pixel traced
uniform int u_scale;
uniform float u_depth_sigma;      // relative depth difference at which the weight falls to 1/e
uniform float u_normal_power;

out vec4 out_gi;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    float depth = texelFetch(u_depth, px, 0).r;
    if (depth <= 0.0) { out_gi = vec4(0.0, 0.0, 0.0, 1.0); return; }
    vec3 n = texelFetch(u_normal, px, 0).xyz;
    ivec2 lo_size = textureSize(u_gi, 0);
    // Trace pixel j covers full pixels [j * s, j * s + s); its sample sits at j * s + s / 2.
    vec2 f = (vec2(px) - float(u_scale / 2)) / float(u_scale);
    ivec2 base = ivec2(floor(f));
    vec2 w = f - vec2(base);
    vec4 sum = vec4(0.0);
    float wsum = 0.0, best = 1e30;
    vec4 nearest = vec4(0.0, 0.0, 0.0, 1.0);
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 q = clamp(base + o, ivec2(0), lo_size - 1);
        vec4 g = texelFetch(u_geom, q, 0);
        vec4 v = texelFetch(u_gi, q, 0);
        float bil = (o.x == 1 ? w.x : 1.0 - w.x) * (o.y == 1 ? w.y : 1.0 - w.y);
        float dz = abs(g.w - depth) / max(depth, 1e-6);
        float wk = (bil + 1e-3) * exp(-dz / u_depth_sigma) * pow(max(dot(n, g.xyz), 0.0), u_normal_power);
        if (g.w <= 0.0) wk = 0.0;
        sum += wk * v;
        wsum += wk;
        if (g.w > 0.0 && abs(g.w - depth) < best) { best = abs(g.w - depth); nearest = v; }
    }
    out_gi = wsum > 1e-4 ? sum / wsum : nearest;
}

#endif
