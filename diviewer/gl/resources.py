"""GPU copies of scene data (meshes, textures) and uniform helpers; scene/ stays GL-free."""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.culling import split_mesh
from diviewer.scene import camera as cam
from diviewer.scene.model import Material, Mesh


def set_uniform(prog: moderngl.Program, name: str, value) -> None:
    """Set a uniform if the program uses it (GLSL compilers drop unused ones)."""
    member = prog.get(name, None) if hasattr(prog, "get") else (prog[name] if name in prog else None)
    if member is None:
        return
    if isinstance(value, np.ndarray) and value.ndim == 2:
        member.write(np.ascontiguousarray(value.T, dtype="f4").tobytes())  # GL is column-major
    elif isinstance(value, np.ndarray) and value.ndim == 3:
        member.write(np.ascontiguousarray(value.transpose(0, 2, 1), dtype="f4").tobytes())
    else:
        member.value = value


class GpuMesh:
    """One mesh's vertex buffer (position, normal, uv interleaved) and index buffer."""

    STRIDE_FORMAT = "3f 3f 2f"

    def __init__(self, ctx: moderngl.Context, mesh: Mesh):
        uv = mesh.uvs if mesh.uvs is not None else np.zeros((len(mesh.vertices), 2), np.float32)
        data = np.hstack([mesh.vertices, mesh.normals, uv]).astype("f4")
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(mesh.faces, dtype="u4").tobytes())
        self.ctx = ctx
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self.triangles = len(mesh.faces)
        self.bounds = np.asarray(mesh.bounds, np.float64) if len(mesh.vertices) else np.zeros((2, 3))
        """Object-space box (2, 3): what culling tests."""

    def vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        """A vertex array for ``prog``, binding only the attributes it declares."""
        key = prog.glo
        if key not in self._vaos:
            names = [n for n in ("in_position", "in_normal", "in_uv") if n in prog]
            fmt = " ".join(f if n in names else f"{f[0]}x4" for f, n in zip(("3f", "3f", "2f"), ("in_position", "in_normal", "in_uv")))
            self._vaos[key] = self.ctx.vertex_array(prog, [(self.vbo, fmt, *names)], self.ibo, index_element_size=4)
        return self._vaos[key]

    def release(self) -> None:
        for v in self._vaos.values():
            v.release()
        self.vbo.release()
        self.ibo.release()


def upload_texture(ctx: moderngl.Context, image: np.ndarray, alpha: np.ndarray | None = None) -> moderngl.Texture:
    """A mipmapped RGBA half-float texture from a top-row-first linear image (alpha 1 where none is given).

    GL's t = 0 is the image's bottom row. Linear floats: mipmaps and bilinear filtering average
    radiometric values, as Mitsuba's bitmap does with the same data. Half floats: half the memory of
    float32 (Sponza's 24 base-colour textures: 62 MB with their mipmaps, not 124), and an 8-bit sRGB
    texel's linear value within 2.5e-4 of its own (11 significant bits; the smallest, 1/255 sRGB,
    is 3e-4 linear, a normal half).
    """
    rgba = np.empty((*image.shape[:2], 4), dtype="f2")
    rgba[..., :3] = image[..., :3]
    rgba[..., 3] = 1.0 if alpha is None else alpha
    img = np.ascontiguousarray(np.flipud(rgba))
    tex = ctx.texture((img.shape[1], img.shape[0]), 4, img.tobytes(), dtype="f2")
    tex.build_mipmaps()
    tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = True
    return tex


def merge_static(meshes: dict[str, Mesh], objects) -> dict[str, Mesh]:
    """Objects that never move, merged per material into one world-space mesh each (one draw call each).

    A mirroring pose has its triangles' winding reversed, so every merged triangle is counter-clockwise
    seen from outside and the identity pose needs no front-face switch.
    """
    groups: dict[str, list] = {}
    for o in objects:
        groups.setdefault(o.material, []).append(o)
    out = {}
    for material, objs in groups.items():
        verts, normals, uvs, faces, base = [], [], [], [], 0
        textured = any(meshes[o.mesh].uvs is not None for o in objs)
        for o in objs:
            mesh, m = meshes[o.mesh], o.matrix()
            verts.append(mesh.vertices @ m[:3, :3].T + m[:3, 3])
            n = mesh.normals @ cam.normal_matrix(m).T
            normals.append(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30))
            if textured:
                uvs.append(mesh.uvs if mesh.uvs is not None else np.zeros((len(mesh.vertices), 2), np.float32))
            f = mesh.faces if np.linalg.det(m[:3, :3]) >= 0 else mesh.faces[:, ::-1]
            faces.append(f.astype(np.uint32) + base)
            base += len(mesh.vertices)
        out[material] = Mesh(f"static:{material}", np.concatenate(verts).astype(np.float32),
                             np.concatenate(normals).astype(np.float32), np.concatenate(faces),
                             np.concatenate(uvs).astype(np.float32) if textured else None, source="merged")
    return out


class GpuScene:
    """All meshes of a scene's library and all material textures, uploaded once."""

    def __init__(self, ctx: moderngl.Context, meshes: dict[str, Mesh], materials: dict[str, Material]):
        self.meshes = {k: GpuMesh(ctx, m) for k, m in meshes.items()}
        self.textures = {k: upload_texture(ctx, m.texture, m.alpha) for k, m in materials.items()
                         if m.texture is not None}
        self.emission_textures = {k: upload_texture(ctx, m.emission_texture) for k, m in materials.items()
                                  if m.emission_texture is not None}
        """Each textured emitter's emission texture (the G-buffer and VXGI multiply the material's emission by it)."""
        self._sources: dict[str, object] = {**meshes, **{f"material:{k}": m for k, m in materials.items()}}
        """What each GPU copy was made from, so ``sync`` uploads only what changed."""
        self.static: list[tuple[str, GpuMesh]] = []
        """The geometry of the objects that never move, merged per material and cut into spatial chunks
        (gl/culling.py): (material, GPU mesh in world space) each (see Renderer)."""
        self.static_key: object = None

    def set_static(self, ctx: moderngl.Context, meshes: dict[str, Mesh], objects, key: object) -> None:
        """Upload the merged, chunked static geometry of ``objects`` (once per ``key``, compared by identity)."""
        if key is self.static_key:
            return
        for _, m in self.static:
            m.release()
        self.static = [(material, GpuMesh(ctx, chunk))
                       for material, mesh in merge_static(meshes, objects).items() for chunk in split_mesh(mesh)]
        self.static_key = key

    def add_mesh(self, ctx: moderngl.Context, mesh: Mesh) -> None:
        if mesh.name in self.meshes:
            self.meshes[mesh.name].release()
        self.meshes[mesh.name] = GpuMesh(ctx, mesh)
        self._sources[mesh.name] = mesh

    def sync(self, ctx: moderngl.Context, scene) -> None:
        """Upload the scene's meshes and material textures that are new or replaced since they were uploaded
        (a mesh file loaded, or loaded again under the same key: objects are compared, not keys)."""
        for key, mesh in scene.meshes.items():
            if self._sources.get(key) is not mesh:
                self.add_mesh(ctx, mesh)
        for key, mat in scene.materials.items():
            if self._sources.get(f"material:{key}") is mat:
                continue
            for textures, image, alpha in ((self.textures, mat.texture, mat.alpha),
                                           (self.emission_textures, mat.emission_texture, None)):
                if key in textures:
                    textures.pop(key).release()
                if image is not None:
                    textures[key] = upload_texture(ctx, image, alpha)
            self._sources[f"material:{key}"] = mat

    def release(self) -> None:
        for m in (*self.meshes.values(), *(g for _, g in self.static)):
            m.release()
        for t in (*self.textures.values(), *self.emission_textures.values()):
            t.release()
