"""The voxel-grid half of VXGIPass (diviewer.gl.vxgi): voxelize, inject, resolve, mip and bounce.

Split from the pass so that each module stays readable; the stages and their artefacts are described
in diviewer.gl.vxgi's docstring. ``VoxelGridPasses`` expects the attributes VXGIPass sets up (ctx,
renderer, settings, shaders, voxels, aniso, levels, _sums, _raster_fbo, _lists, grid_min, grid_size).
"""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.resources import set_uniform
from diviewer.gl.shadow_fit import light_defines
from diviewer.scene import camera as cam
from diviewer.scene.model import FrameConfig, Object

_FRAG_BYTES = 48  # three vec4 per voxel fragment

class FragmentList:
    """A voxel fragment list on the GPU: a (count, capacity) header and the fragments."""

    def __init__(self, ctx: moderngl.Context, capacity: int):
        self.ctx = ctx
        self.header = ctx.buffer(reserve=8)
        self.capacity = 0
        self.frags = None
        self.count = 0
        self.grow(capacity)

    def grow(self, capacity: int) -> None:
        if self.frags is not None:
            self.frags.release()
        self.capacity = int(capacity)
        self.frags = self.ctx.buffer(reserve=max(self.capacity, 1) * _FRAG_BYTES)

    def release(self) -> None:
        self.header.release()
        self.frags.release()


class VoxelGridPasses:
    """Builds the voxel grid each frame that needs it (mixed into VXGIPass)."""

    def _voxelize(self, lst: FragmentList, objects: list[Object]) -> None:
        ctx = self.ctx
        self._per_fragment("CLEAR", [lst])  # empty the voxels the list's old fragments filled
        prog = self.shaders.program("vxgi_voxelize.glsl")
        self._grid_uniforms(prog)
        self._raster_fbo.use()
        ctx.enable_only(moderngl.NOTHING)  # no depth test, no culling: every triangle, both sides
        while True:
            lst.header.write(np.array([0, lst.capacity], dtype="u4").tobytes())
            lst.header.bind_to_storage_buffer(0)
            lst.frags.bind_to_storage_buffer(1)
            for obj in objects:
                model = obj.matrix()
                set_uniform(prog, "m_model", model)
                set_uniform(prog, "m_normal", cam.normal_matrix(model))
                mat = self.scene.materials[obj.material]
                set_uniform(prog, "u_albedo", tuple(float(x) for x in mat.albedo))
                set_uniform(prog, "u_emission", tuple(float(x) for x in mat.emission))
                tex = self.renderer.gpu.textures.get(obj.material)
                set_uniform(prog, "u_has_texture", tex is not None)
                if tex is not None:
                    tex.use(location=0)
                    set_uniform(prog, "u_albedo_map", 0)
                glow = self.renderer.gpu.emission_textures.get(obj.material)
                set_uniform(prog, "u_has_emission_map", glow is not None)
                if glow is not None:
                    glow.use(location=1)
                    set_uniform(prog, "u_emission_map", 1)
                self.renderer.gpu.meshes[obj.mesh].vao(prog).render(moderngl.TRIANGLES)
            ctx.memory_barrier()
            count = int(np.frombuffer(lst.header.read(4), dtype="u4")[0])
            if count <= lst.capacity:
                break
            lst.grow(int(count * 1.25) + 1024)  # the list overflowed: draw again into a longer one
        lst.count = count

    def _inject(self, config: FrameConfig) -> None:
        ctx = self.ctx
        r = self.renderer
        self._sums.bind_to_storage_buffer(2)
        first = True
        for light in config.lights or (None,):
            shadow = None
            if light is None:
                prog = self.shaders.compute("vxgi_inject.glsl")
            else:
                # This frame's shadow map of the light, as the renderer's direct pass used it.
                shadow = r.shadow_pass.maps.get(light.name)
                prog = self.shaders.compute("vxgi_inject.glsl", light_defines(light))
                self.renderer.set_light_uniforms(prog, light, shadow)
            set_uniform(prog, "u_first", first)
            for lst in self._lists.values():
                if lst.count == 0:
                    continue
                lst.header.bind_to_storage_buffer(0)
                lst.frags.bind_to_storage_buffer(1)
                prog.run(group_x=-(-lst.count // 64))
                ctx.memory_barrier()
            first = False
        self._per_fragment("RESOLVE")

    def _per_fragment(self, mode: str, lists=None) -> None:
        """Run vxgi_resolve.glsl in ``mode`` (RESOLVE, ZERO or CLEAR) over the voxels of fragment lists."""
        prog = self.shaders.compute("vxgi_resolve.glsl", {mode: 1})
        set_uniform(prog, "u_res", int(self.settings.resolution))
        self._sums.bind_to_storage_buffer(2)
        self.voxels.bind_to_image(0, read=False, write=True, level=0)
        for lst in lists or self._lists.values():
            if lst.count:
                lst.header.bind_to_storage_buffer(0)
                lst.frags.bind_to_storage_buffer(1)
                prog.run(group_x=-(-lst.count // 64))
        self.ctx.memory_barrier()

    def _build_mips(self) -> None:
        if self.aniso:
            self._build_aniso_mips()
            return
        prog = self.shaders.compute("vxgi_mip.glsl")
        self.voxels.use(location=0)
        set_uniform(prog, "u_fine", 0)
        for level in range(self.levels - 1):
            side = self.settings.resolution >> (level + 1)
            set_uniform(prog, "u_level", level)
            set_uniform(prog, "u_res", side)
            self.voxels.bind_to_image(0, read=False, write=True, level=level + 1)
            prog.run(group_x=-(-side // 4), group_y=-(-side // 4), group_z=-(-side // 4))
            self.ctx.memory_barrier()

    def _build_aniso_mips(self) -> None:
        prog = self.shaders.compute("vxgi_mip.glsl", {"ANISO": 1})
        self.voxels.use(location=0)
        set_uniform(prog, "u_iso", 0)
        for i, t in enumerate(self.aniso):
            t.use(location=1 + i)
        prog["u_src"].value = tuple(range(1, 7))
        for level in range(self.levels - 1):  # directional level k is grid level k + 1
            side = self.settings.resolution >> (level + 1)
            set_uniform(prog, "u_from_iso", level == 0)
            set_uniform(prog, "u_level", max(level - 1, 0))
            set_uniform(prog, "u_res", side)
            for i, t in enumerate(self.aniso):
                t.bind_to_image(i, read=False, write=True, level=level)
            prog.run(group_x=-(-side // 4), group_y=-(-side // 4), group_z=-(-side // 4))
            self.ctx.memory_barrier()

    def _bounce(self) -> None:
        """A second bounce: fragments gather the first-bounce grid, then resolve and filter again."""
        prog = self.shaders.compute("vxgi_bounce.glsl", self._defines)
        self._cone_uniforms(prog, 0)
        self._sums.bind_to_storage_buffer(2)
        for lst in self._lists.values():
            if lst.count:
                lst.header.bind_to_storage_buffer(0)
                lst.frags.bind_to_storage_buffer(1)
                prog.run(group_x=-(-lst.count // 64))
        self.ctx.memory_barrier()
        self._per_fragment("RESOLVE")
        self._build_mips()
