// Display encoding shared by composite.glsl and view.glsl: exposure (stops), tone curve, sRGB.
// The including shader declares `uniform float u_exposure;` and `uniform int u_tonemap;`.

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

vec3 aces(vec3 x) {   // Narkowicz's fit
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 tonemap(vec3 c) {   // u_tonemap 0: clamp, 1: Reinhard, 2: ACES
    // Clamped before the curve: x * (2.51 x + ...) overflows to inf / inf = NaN for huge radiance.
    c = min(max(c, 0.0) * exp2(u_exposure), vec3(1e4));
    if (u_tonemap == 1) c = c / (1.0 + c);
    else if (u_tonemap == 2) c = aces(c);
    return srgb(c);
}
