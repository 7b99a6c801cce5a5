// Packs the G-buffer into the neural model's input: float32 NHWC, rows top first, in one storage
// buffer, so the CPU reads it once and reshuffles nothing. The channel layout is not written here:
// gl/neural.py injects it from diviewer.encoding.INPUT_CHANNELS as defines (IN_CHANNELS, the total,
// IN_<NAME>, where each buffer starts, and IN_<NAME>_N, its component count, checked below).
#if defined COMPUTE_SHADER

#if !defined IN_CHANNELS || !defined IN_DEPTH || !defined IN_NORMAL || !defined IN_ALBEDO || !defined IN_DIRECT
#error "pack.glsl needs the channel layout defines from diviewer.gl.neural"
#endif
#if IN_DEPTH_N != 1 || IN_NORMAL_N != 3 || IN_ALBEDO_N != 3 || IN_DIRECT_N != 3
#error "the encoding's channel counts differ from what pack.glsl writes (1 depth, 3 normal, albedo, direct)"
#endif

layout(local_size_x = 8, local_size_y = 8) in;

uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform sampler2D u_albedo;
uniform sampler2D u_direct;
uniform ivec2 u_size;

layout(std430, binding = 0) writeonly buffer Packed { float data[]; };

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= u_size.x || p.y >= u_size.y) return;
    int base = ((u_size.y - 1 - p.y) * u_size.x + p.x) * IN_CHANNELS;
    vec3 n = texelFetch(u_normal, p, 0).xyz;
    vec3 a = texelFetch(u_albedo, p, 0).rgb;
    vec3 d = texelFetch(u_direct, p, 0).rgb;
    data[base + IN_DEPTH] = texelFetch(u_depth, p, 0).r;
    data[base + IN_NORMAL] = n.x; data[base + IN_NORMAL + 1] = n.y; data[base + IN_NORMAL + 2] = n.z;
    data[base + IN_ALBEDO] = a.r; data[base + IN_ALBEDO + 1] = a.g; data[base + IN_ALBEDO + 2] = a.b;
    data[base + IN_DIRECT] = d.r; data[base + IN_DIRECT + 1] = d.g; data[base + IN_DIRECT + 2] = d.b;
}

#endif
