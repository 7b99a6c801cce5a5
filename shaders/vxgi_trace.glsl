// VXGI diffuse cone tracing from the G-buffer, one pixel of the trace resolution per fragment (a
// lower trace resolution reads the G-buffer at the centre of its block). Each cone starts a distance
// u_offset (in voxels) off the surface along the normal and marches front to back through the mip
// chain: the sample diameter grows with distance (2 tan(aperture / 2) t), the mip level is
// log2(diameter / voxel) and the step is u_step times the diameter, with the opacity corrected to
// the step length. Cones that leave the grid see the scene's ambient sky through what they did not
// hit. Out: (indirect, AO) with indirect = E / pi (the cosine-weighted mean incoming radiance, so the
// outgoing indirect radiance is albedo * indirect) and AO the unoccluded fraction within u_ao_dist;
// and the (view normal, depth) of the pixel traced, for the depth/normal-aware upsampling.
#if defined VERTEX_SHADER
#include "fullscreen.glsl"
#elif defined FRAGMENT_SHADER

#define MAX_CONES 16

uniform sampler2D u_depth;
uniform sampler2D u_normal;
uniform sampler3D u_voxels;

uniform mat4 m_inv_view;          // camera to world
uniform vec2 u_tan_half_fov;      // (tan(fov_y / 2) * aspect, tan(fov_y / 2))
uniform int u_scale;              // full-resolution pixels per trace pixel (per side)

uniform vec3 u_grid_min;
uniform float u_grid_size;        // world side of the grid
uniform float u_voxel;            // world side of a level-0 voxel
uniform float u_max_lod;

uniform int u_cones;
uniform vec3 u_cone_dirs[MAX_CONES];     // tangent space, z along the normal
uniform float u_cone_weights[MAX_CONES]; // cosine-weighted share of the hemisphere; they sum to 1
uniform float u_tan_half_aperture;
uniform float u_step;             // step length / sample diameter
uniform float u_offset;           // start offset along the normal, in voxels
uniform float u_lift;             // samples stay u_lift sample radii above the tangent plane
uniform float u_max_dist;         // world
uniform float u_ao_dist;          // world
uniform vec3 u_ambient;           // sky radiance outside the grid

layout(location = 0) out vec4 out_gi;
layout(location = 1) out vec4 out_geom;

// One cone: (radiance reaching the apex, occlusion within u_ao_dist).
vec4 cone(vec3 origin, vec3 dir, vec3 n) {
    float rise = dot(dir, n);
    vec3 c = vec3(0.0);
    float a = 0.0, ao = 0.0;
    float t = u_voxel;
    bool escaped = true;
    while (a < 0.98) {
        if (t > u_max_dist) { escaped = false; break; }
        float diam = max(u_voxel, 2.0 * u_tan_half_aperture * t);
        // Keep the sample's footprint off the surface the cone starts on (self-occlusion, self-illumination).
        float lift = max(u_lift * 0.5 * diam - t * rise, 0.0);
        vec3 uvw = (origin + dir * t + n * lift - u_grid_min) / u_grid_size;
        if (any(lessThan(uvw, vec3(0.0))) || any(greaterThan(uvw, vec3(1.0)))) break;
        vec4 s = textureLod(u_voxels, uvw, min(log2(diam / u_voxel), u_max_lod));
        // Coverage is per sample diameter; a step of u_step diameters sees (1 - (1 - a)^u_step).
        float sa = 1.0 - pow(max(1.0 - s.a, 0.0), u_step);
        vec3 sc = s.a > 1e-6 ? s.rgb * (sa / s.a) : vec3(0.0);
        c += (1.0 - a) * sc;
        if (t <= u_ao_dist) ao += (1.0 - a) * sa;
        a += (1.0 - a) * sa;
        t += diam * u_step;
    }
    if (escaped) c += (1.0 - a) * u_ambient;
    return vec4(c, min(ao, 1.0));
}

void main() {
    ivec2 size = textureSize(u_depth, 0);
    ivec2 px = min(ivec2(gl_FragCoord.xy) * u_scale + u_scale / 2, size - 1);
    float depth = texelFetch(u_depth, px, 0).r;
    vec3 n_view = texelFetch(u_normal, px, 0).xyz;
    out_geom = vec4(n_view, depth);
    if (depth <= 0.0) { out_gi = vec4(0.0, 0.0, 0.0, 1.0); return; }   // background
    vec2 ndc = ((vec2(px) + 0.5) / vec2(size)) * 2.0 - 1.0;
    vec3 p = (m_inv_view * vec4(depth * vec3(ndc * u_tan_half_fov, -1.0), 1.0)).xyz;
    vec3 n = normalize(mat3(m_inv_view) * n_view);
    // Orthonormal basis about n (Duff et al. 2017): continuous except across n.z = 0's sign.
    float sgn = n.z >= 0.0 ? 1.0 : -1.0;
    float aa = -1.0 / (sgn + n.z);
    float bb = n.x * n.y * aa;
    vec3 t1 = vec3(1.0 + sgn * n.x * n.x * aa, sgn * bb, -sgn * n.x);
    vec3 t2 = vec3(bb, sgn + n.y * n.y * aa, -n.y);
    vec3 origin = p + n * (u_offset * u_voxel);
    vec3 irr = vec3(0.0);
    float occ = 0.0;
    for (int k = 0; k < u_cones; ++k) {
        vec3 d = u_cone_dirs[k];
        vec4 r = cone(origin, normalize(t1 * d.x + t2 * d.y + n * d.z), n);
        irr += u_cone_weights[k] * r.rgb;
        occ += u_cone_weights[k] * r.a;
    }
    out_gi = vec4(irr, 1.0 - occ);
}

#endif
