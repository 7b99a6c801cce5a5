// Display: exposure (stops), tone map, sRGB encoding. Samples the HDR image bilinearly, so an image at
// another resolution (the GI pass's) is scaled to the viewport.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

in vec2 v_uv;

uniform sampler2D u_hdr;
uniform float u_exposure;   // stops
uniform int u_tonemap;      // 0: clamp, 1: Reinhard, 2: ACES (Narkowicz fit)
uniform bool u_flip_y;      // the image's rows run top first (the neural pass's output)

out vec4 out_color;

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

void main() {
    vec3 c = texture(u_hdr, u_flip_y ? vec2(v_uv.x, 1.0 - v_uv.y) : v_uv).rgb;
    // Non-finite input (a broken buffer) shows as magenta rather than poisoning the display.
    if (any(isnan(c)) || any(isinf(c))) { out_color = vec4(1.0, 0.0, 1.0, 1.0); return; }
    // Clamped before the curve: x * (2.51 x + ...) overflows to inf / inf = NaN for huge radiance.
    c = min(max(c, 0.0) * exp2(u_exposure), vec3(1e4));
    if (u_tonemap == 1) c = c / (1.0 + c);
    else if (u_tonemap == 2) c = aces(c);
    out_color = vec4(srgb(c), 1.0);
}

#endif
