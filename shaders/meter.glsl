// Auto exposure's meter: the shown radiance image sampled at the centres of a fixed METER x METER grid of
// cells (texelFetch of the texel under each centre: no filtering, the same samples whatever the size),
// written as RGB to a storage buffer that viewer/exposure.py averages. 4,096 texels instead of a
// full-resolution reduction: metering needs the frame's brightness, not its every pixel.
#if defined COMPUTE_SHADER

layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 0) writeonly buffer Samples { float samples[]; };
uniform sampler2D u_image;

void main() {
    ivec2 c = ivec2(gl_GlobalInvocationID.xy);
    if (c.x >= METER || c.y >= METER) return;
    ivec2 size = textureSize(u_image, 0);
    ivec2 p = min(ivec2((vec2(c) + 0.5) * vec2(size) / float(METER)), size - 1);
    vec3 rgb = texelFetch(u_image, p, 0).rgb;
    int i = (c.y * METER + c.x) * 3;
    samples[i] = rgb.r;
    samples[i + 1] = rgb.g;
    samples[i + 2] = rgb.b;
}

#endif
