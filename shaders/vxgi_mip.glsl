// VXGI mip chain, one invocation per voxel of level L + 1 from its 8 children in level L.
// Coverage: the children's opacity seen along each axis (the 4 pairs of children in a row composited,
// a + b - ab, and averaged), and of the three axes the most opaque. The plain mean of the children
// (their volume fraction) would make a wall one voxel thick half transparent at each coarser level, so
// that cones pass through walls and lose most of the light (a closed glowing box: 0.2-0.4 of the
// radiance at 128^3); the axis maximum keeps a wall opaque at every level and a lone voxel at its
// projected area (1/4, 1/16, ...). Radiance: the coverage-weighted mean of the children's, stored
// premultiplied. A coarse voxel shows the same radiance in every direction (an isotropic mip, the root
// of light leaking; see vxgi.py).
//
// ANISO: six directional grids instead (Crassin et al. 2011), each for cones travelling along one of
// +x, -x, +y, -y, +z, -z: a parent is the mean over its 4 rows of children along that axis of the
// row composited front to back (the child the cone reaches first in front). A wall then hides what is
// behind it at every level, from whichever side it is seen (no leaking through walls at least a
// level-0 voxel apart), and a cone running along a wall is not stopped by it. Level 1 (u_from_iso) is
// built from the isotropic level 0.
#if defined COMPUTE_SHADER

layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;

#if defined ANISO

uniform sampler3D u_iso;                        // the isotropic grid; level 0 is read
uniform sampler3D u_src[6];                     // the directional grids; level u_level is read
uniform bool u_from_iso;
uniform int u_level;
uniform int u_res;                              // side of the level written
layout(rgba16f, binding = 0) writeonly uniform image3D u_dst[6];

vec4 child(int dir, ivec3 p) {
    return u_from_iso ? texelFetch(u_iso, p, 0) : texelFetch(u_src[dir], p, u_level);
}

void main() {
    ivec3 v = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(v, ivec3(u_res)))) return;
    for (int dir = 0; dir < 6; ++dir) {
        int axis = dir >> 1;
        bool forward = (dir & 1) == 0;
        ivec3 e = ivec3(axis == 0, axis == 1, axis == 2);
        ivec3 u = e.yzx, w = e.zxy;   // the two other axes
        vec4 sum = vec4(0.0);
        for (int k = 0; k < 4; ++k) {
            ivec3 p = 2 * v + u * (k & 1) + w * (k >> 1);
            vec4 a = child(dir, p), b = child(dir, p + e);
            vec4 front = forward ? a : b, back = forward ? b : a;
            sum += front + (1.0 - front.a) * back;
        }
        imageStore(u_dst[dir], v, sum * 0.25);
    }
}

#else

uniform sampler3D u_fine;                       // the whole grid; level u_level is read
uniform int u_level;
uniform int u_res;                              // side of level u_level + 1
layout(rgba16f, binding = 0) writeonly uniform image3D u_coarse;

void main() {
    ivec3 v = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(v, ivec3(u_res)))) return;
    vec4 c[8];
    vec4 sum = vec4(0.0);
    for (int k = 0; k < 8; ++k) {   // k = x + 2 y + 4 z
        c[k] = texelFetch(u_fine, 2 * v + ivec3(k & 1, (k >> 1) & 1, k >> 2), u_level);
        sum += c[k];
    }
    vec3 axis = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        // the pair along x differs in bit 0, along y in bit 1, along z in bit 2
        int ix = 2 * k, iy = (k & 1) + 4 * (k >> 1), iz = k;
        float ax = c[ix].a, bx = c[ix + 1].a;
        float ay = c[iy].a, by = c[iy + 2].a;
        float az = c[iz].a, bz = c[iz + 4].a;
        axis += vec3(ax + bx - ax * bx, ay + by - ay * by, az + bz - az * bz);
    }
    float alpha = max(max(axis.x, axis.y), axis.z) * 0.25;
    vec3 radiance = sum.a > 0.0 ? sum.rgb / sum.a : vec3(0.0);
    imageStore(u_coarse, v, vec4(radiance * alpha, alpha));
}

#endif
#endif
