// VXGI voxelization: each triangle is rasterised onto the grid face of its dominant axis (the axis of
// its largest normal component, so it covers the most pixels and leaves no holes along that axis), one
// pixel per voxel column. Each fragment appends a voxel fragment (world position, normal, albedo,
// emission, voxel index) to a list; the light is injected from that list later (vxgi_inject.glsl), so
// a moving light never needs the geometry rasterised again. No conservative rasterisation (llvmpipe
// has none): a triangle thinner than a voxel can miss every pixel centre and leave a gap.
#if defined VERTEX_SHADER

in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;

uniform mat4 m_model;
uniform mat3 m_normal;      // inverse transpose of m_model's upper 3x3 (world-space normals)

out vec3 vs_world;
out vec3 vs_normal;
out vec2 vs_uv;

void main() {
    vec4 w = m_model * vec4(in_position, 1.0);
    vs_world = w.xyz;
    vs_normal = m_normal * in_normal;
    vs_uv = in_uv;
    gl_Position = w;
}

#elif defined GEOMETRY_SHADER

layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;

in vec3 vs_world[];
in vec3 vs_normal[];
in vec2 vs_uv[];

uniform vec3 u_grid_min;    // world position of the grid's corner
uniform float u_grid_size;  // world side of the (cubic) grid

out vec3 g_world;
out vec3 g_normal;
out vec2 g_uv;

void main() {
    vec3 fn = abs(cross(vs_world[1] - vs_world[0], vs_world[2] - vs_world[0]));
    int axis = (fn.x >= fn.y && fn.x >= fn.z) ? 0 : (fn.y >= fn.z ? 1 : 2);
    for (int i = 0; i < 3; ++i) {
        vec3 g = (vs_world[i] - u_grid_min) / u_grid_size * 2.0 - 1.0;
        vec2 xy = axis == 0 ? g.yz : (axis == 1 ? g.zx : g.xy);
        gl_Position = vec4(xy, 0.0, 1.0);
        g_world = vs_world[i];
        g_normal = vs_normal[i];
        g_uv = vs_uv[i];
        EmitVertex();
    }
    EndPrimitive();
}

#elif defined FRAGMENT_SHADER

in vec3 g_world;
in vec3 g_normal;
in vec2 g_uv;

uniform vec3 u_grid_min;
uniform float u_grid_size;
uniform int u_res;
uniform vec3 u_albedo;
uniform vec3 u_emission;
uniform bool u_has_texture;
uniform sampler2D u_albedo_map;
uniform bool u_has_emission_map;
uniform sampler2D u_emission_map;  // u_emission multiplies it

layout(std430, binding = 0) buffer Counter { uint count; uint capacity; };
// Three vec4 per fragment: (world position, voxel index), (normal, albedo.rg), (emission, albedo.b).
layout(std430, binding = 1) writeonly buffer Fragments { vec4 frags[]; };

layout(location = 0) out vec4 out_unused;   // the framebuffer needs an attachment; its mask is off

void main() {
    ivec3 v = clamp(ivec3(floor((g_world - u_grid_min) / u_grid_size * float(u_res))), ivec3(0), ivec3(u_res - 1));
    uint slot = atomicAdd(count, 1u);
    out_unused = vec4(0.0);
    if (slot >= capacity) return;   // the list is too short: the caller reads count, grows it, draws again
    vec3 albedo = u_albedo;
    // Derivatives here are per voxel, so the mip level matches the voxel's footprint on the texture.
    if (u_has_texture) albedo *= texture(u_albedo_map, g_uv).rgb;
    vec3 emission = u_emission;
    if (u_has_emission_map) emission *= texture(u_emission_map, g_uv).rgb;
    uint index = uint(v.x + u_res * (v.y + u_res * v.z));
    frags[3u * slot] = vec4(g_world, uintBitsToFloat(index));
    // Albedo as half floats in the two spare components (8-bit would round 0.73 to 0.729).
    frags[3u * slot + 1u] = vec4(normalize(g_normal), uintBitsToFloat(packHalf2x16(albedo.rg)));
    frags[3u * slot + 2u] = vec4(emission, uintBitsToFloat(packHalf2x16(vec2(albedo.b, 0.0))));
}

#endif
