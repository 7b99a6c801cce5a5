// VXGI cone marching through the voxel mip chain, shared by the screen trace (vxgi_trace.glsl) and
// the second bounce (vxgi_bounce.glsl). Each cone starts u_offset voxels off the surface along the
// normal and marches front to back: the sample diameter grows with distance (2 tan(aperture / 2) t),
// the mip level is log2(diameter / voxel) - u_lod_bias, the step is u_step diameters with the
// opacity corrected to the step length, and each sample is lifted off the tangent plane by u_lift of
// its radius. Cones that leave the grid see the scene's ambient sky through what they did not hit.

#define MAX_CONES 16

uniform sampler3D u_voxels;       // isotropic: level 0, and with ANISO the only level used
#if defined ANISO
// Directional grids (vxgi_mip.glsl), one level coarser than u_voxels: for cones travelling +x, -x, ...
uniform sampler3D u_aniso_px, u_aniso_nx, u_aniso_py, u_aniso_ny, u_aniso_pz, u_aniso_nz;
#endif
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
uniform float u_lod_bias;         // sample this many levels finer than the cone diameter asks
uniform float u_max_dist;         // world
uniform float u_ao_dist;          // world
uniform vec3 u_ambient;           // sky radiance outside the grid

// The grid seen by a cone travelling along dir, at mip level lod.
vec4 sample_grid(vec3 uvw, float lod, vec3 dir) {
#if defined ANISO
    // The three directional grids facing the cone, weighted by dir's squared components.
    float l = max(lod - 1.0, 0.0);
    vec3 w = dir * dir;
    vec4 s = w.x * (dir.x >= 0.0 ? textureLod(u_aniso_px, uvw, l) : textureLod(u_aniso_nx, uvw, l))
           + w.y * (dir.y >= 0.0 ? textureLod(u_aniso_py, uvw, l) : textureLod(u_aniso_ny, uvw, l))
           + w.z * (dir.z >= 0.0 ? textureLod(u_aniso_pz, uvw, l) : textureLod(u_aniso_nz, uvw, l));
    return lod < 1.0 ? mix(textureLod(u_voxels, uvw, 0.0), s, lod) : s;
#else
    return textureLod(u_voxels, uvw, lod);
#endif
}

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
        float lod = clamp(log2(diam / u_voxel) - u_lod_bias, 0.0, u_max_lod);
        vec4 s = sample_grid(uvw, lod, dir);
        // Coverage is per voxel of the level sampled; a step of length L through voxels of side v sees
        // 1 - (1 - a)^(L / v) (L / v = u_step without a lod bias or clamping). A finer level sampled at
        // the cone's pace can step over a thin wall; the exponent makes up for it on average.
        float sa = 1.0 - pow(max(1.0 - s.a, 0.0), diam * u_step / (u_voxel * exp2(lod)));
        vec3 sc = s.a > 1e-6 ? s.rgb * (sa / s.a) : vec3(0.0);
        c += (1.0 - a) * sc;
        if (t <= u_ao_dist) ao += (1.0 - a) * sa;
        a += (1.0 - a) * sa;
        t += diam * u_step;
    }
    if (escaped) c += (1.0 - a) * u_ambient;
    return vec4(c, min(ao, 1.0));
}

// All cones about the normal n at p: (indirect = E / pi, occlusion within u_ao_dist), both weighted.
vec4 gather(vec3 p, vec3 n) {
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
    return vec4(irr, occ);
}
