// The viewer's display of a view mode: one image, two side by side (split) or their difference, each
// shown according to what it holds (radiance, raw values, depth, normals, albedo). Radiance uses the
// same exposure, tone curves and sRGB encoding as composite.glsl.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

in vec2 v_uv;

uniform sampler2D u_a;
uniform sampler2D u_b;
uniform int u_kind_a;       // 0: radiance, 1: raw, 2: depth, 3: normal, 4: albedo
uniform int u_kind_b;
uniform bool u_flip_a;      // the image's rows run top first (neural output, path-traced reference)
uniform bool u_flip_b;
uniform int u_layout;       // 0: A alone, 1: split (A left, B right), 2: |A - B|
uniform float u_split;      // divider position, fraction of the width
uniform float u_line;       // divider half-width, fraction of the width
uniform float u_exposure;   // stops
uniform int u_tonemap;      // 0: clamp, 1: Reinhard, 2: ACES (as composite.glsl)
uniform vec2 u_depth_range; // view-space depth shown brightest / darkest
uniform float u_diff_gain;  // multiplier of the difference

out vec4 out_color;

#include "tonemap.glsl"

vec3 fetch(sampler2D tex, bool flip, int kind) {
    vec4 t = texture(tex, flip ? vec2(v_uv.x, 1.0 - v_uv.y) : v_uv);
    return kind == 2 ? t.rrr : t.rgb;
}

vec3 show(vec3 c, int kind) {
    if (any(isnan(c)) || any(isinf(c))) return vec3(1.0, 0.0, 1.0);
    if (kind == 0) return tonemap(c);
    if (kind == 1) return srgb(c);
    if (kind == 2) {   // as imageio.depth_preview: near bright, far dark, background black
        if (c.r <= 0.0) return vec3(0.0);
        float t = clamp((c.r - u_depth_range.x) / max(u_depth_range.y - u_depth_range.x, 1e-6), 0.0, 1.0);
        return vec3(1.0 - 0.85 * t);
    }
    if (kind == 3) return c == vec3(0.0) ? vec3(0.0) : clamp(c * 0.5 + 0.5, 0.0, 1.0);
    return srgb(c);
}

void main() {
    vec3 a = fetch(u_a, u_flip_a, u_kind_a);
    if (u_layout == 1) {
        if (abs(v_uv.x - u_split) < u_line) { out_color = vec4(1.0, 0.8, 0.2, 1.0); return; }
        out_color = vec4(v_uv.x < u_split ? show(a, u_kind_a) : show(fetch(u_b, u_flip_b, u_kind_b), u_kind_b), 1.0);
    } else if (u_layout == 2) {
        vec3 d = abs(a - fetch(u_b, u_flip_b, u_kind_b)) * u_diff_gain;
        out_color = vec4(u_kind_a == 0 ? tonemap(d) : show(d, 1), 1.0);
    } else {
        out_color = vec4(show(a, u_kind_a), 1.0);
    }
}

#endif
