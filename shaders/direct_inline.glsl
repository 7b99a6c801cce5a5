// The direct light of one pixel computed where it is needed, exactly as the direct pass (direct.glsl)
// computes it, for a frame with at most one light: the neural pass's pack and upsample read the
// G-buffer anyway, so they skip the full-resolution direct pass, its target and its read-back.
// Without INLINE_DIRECT, direct_at() reads the direct pass's target (u_direct) instead.
// DIRECTIONAL or POINT_LIGHT selects the light (neither: no light), EMISSIVE adds the emission buffer
// (after the light, as the direct pass's blend does). Texture units: u_direct or u_emission and the
// shadow map are the caller's to bind (gl/neural.py).
#if defined INLINE_DIRECT
#define SHADOW_LOOKUP 1
#include "direct.glsl"
#undef SHADOW_LOOKUP
#if defined EMISSIVE
uniform sampler2D u_emission;
#endif
#else
uniform sampler2D u_direct;
#endif

// Pixel ``p`` of a G-buffer of ``size`` with depth ``z``, view-space normal ``n`` and ``albedo``.
vec3 direct_at(ivec2 p, vec2 size, float z, vec3 n, vec3 albedo) {
#if defined INLINE_DIRECT
    vec3 d = vec3(0.0);
    if (z > 0.0) {
#if defined DIRECTIONAL || defined POINT_LIGHT
        d = light_term(vec2(p) + 0.5, size, z, n, albedo);
#endif
#if defined EMISSIVE
        d += texelFetch(u_emission, p, 0).rgb;
#endif
    }
    return d;
#else
    return texelFetch(u_direct, p, 0).rgb;
#endif
}
