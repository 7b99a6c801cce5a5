// Neural GI composite at the window's resolution: the network's indirect light, predicted at the GI
// resolution and demodulated by gi_guide.glsl, upsampled with a joint bilateral filter guided by the
// full-resolution depth and normals, multiplied by each pixel's albedo and added to the full-resolution
// direct light (read from the direct pass's target, or with INLINE_DIRECT computed here:
// direct_inline.glsl).
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

in vec2 v_uv;

uniform sampler2D u_depth;      // full resolution
uniform sampler2D u_normal;
uniform sampler2D u_albedo;
uniform sampler2D u_irradiance_depth;  // GI resolution (gi_guide.glsl): indirect / albedo, depth
uniform sampler2D u_guide_normal;      // GI resolution: normal
uniform ivec2 u_gi_size;
uniform float u_depth_sigma;    // relative depth difference at which a texel's weight falls to 1/e
uniform float u_normal_power;   // exponent of the normals' cosine
uniform bool u_indirect_only;   // write the upsampled indirect light (albedo x irradiance) alone

out vec4 out_color;

#include "direct_inline.glsl"

struct Texel { float depth; vec3 normal; vec3 indirect; };

Texel gi_texel(ivec2 t) {
    vec4 a = texelFetch(u_irradiance_depth, t, 0);
    return Texel(a.a, texelFetch(u_guide_normal, t, 0).xyz, a.rgb);
}

// How much a GI texel speaks for this pixel: same surface (depth within a fraction of the pixel's) and
// same orientation. Background (depth 0) matches only background.
float similarity(Texel g, float z, vec3 n) {
    if (z <= 0.0 || g.depth <= 0.0) return (z <= 0.0 && g.depth <= 0.0) ? 1.0 : 0.0;
    float dz = (g.depth - z) / (u_depth_sigma * z);
    float cn = max(dot(g.normal, n), 0.0);
    return exp(-dz * dz) * pow(cn, u_normal_power);
}

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float z = texelFetch(u_depth, p, 0).r;
    vec3 n = texelFetch(u_normal, p, 0).xyz;
    vec3 albedo = texelFetch(u_albedo, p, 0).rgb;
    vec3 direct = direct_at(p, vec2(textureSize(u_depth, 0)), z, n, albedo);
    // This pixel's centre in GI texel coordinates; its 2x2 bilinear neighbours, weighted by similarity.
    vec2 g = v_uv * vec2(u_gi_size) - 0.5;
    ivec2 g0 = ivec2(floor(g));
    vec2 f = g - vec2(g0);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
            ivec2 t = clamp(g0 + ivec2(i, j), ivec2(0), u_gi_size - 1);
            Texel gt = gi_texel(t);
            float w = (i == 1 ? f.x : 1.0 - f.x) * (j == 1 ? f.y : 1.0 - f.y) * similarity(gt, z, n);
            sum += w * gt.indirect;
            wsum += w;
        }
    vec3 indirect;
    if (wsum > 1e-4) {
        indirect = sum / wsum;
    } else {
        // No neighbour is this surface (a thin object, a silhouette, a depth discontinuity at every texel):
        // the closest texel of the 4x4 around the pixel in depth and orientation, never a background texel
        // for a surface pixel (no light borrowed from the sky), none at all when there is no such texel.
        float best = 1e30;
        indirect = vec3(0.0);
        for (int j = -1; j < 3; ++j)
            for (int i = -1; i < 3; ++i) {
                ivec2 t = clamp(g0 + ivec2(i, j), ivec2(0), u_gi_size - 1);
                Texel gt = gi_texel(t);
                if ((gt.depth <= 0.0) != (z <= 0.0)) continue;
                float d = z > 0.0 ? abs(gt.depth - z) / (u_depth_sigma * z) + 4.0 * (1.0 - dot(gt.normal, n)) : 0.0;
                if (d < best) { best = d; indirect = gt.indirect; }
            }
    }
    vec3 c = u_indirect_only ? albedo * indirect : direct + albedo * indirect;
    out_color = vec4(max(c, vec3(0.0)), 1.0);
}

#endif
