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

#include "tonemap.glsl"

void main() {
    vec3 c = texture(u_hdr, u_flip_y ? vec2(v_uv.x, 1.0 - v_uv.y) : v_uv).rgb;
    // Non-finite input (a broken buffer) shows as magenta rather than poisoning the display.
    if (any(isnan(c)) || any(isinf(c))) { out_color = vec4(1.0, 0.0, 1.0, 1.0); return; }
    out_color = vec4(tonemap(c), 1.0);
}

#endif
