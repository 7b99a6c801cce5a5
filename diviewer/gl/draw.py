"""A pass's draw of the frame's objects, shared by the G-buffer pass (`diviewer.gl.renderer`) and the shadow maps
(`diviewer.gl.shadow_pass`): the draw list (static geometry merged and chunked, moving objects one by one), culled
against the pass's frustum, drawn with a program of shaders/ whose uniforms the pass gives as values.

Both passes hand their renderer in: its context, scene, GPU copies, shader cache and culling settings are read,
its draw counters written; nothing here calls back into the renderer or the pass.
"""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.context import gl_flush
from diviewer.gl.culling import boxes_visible, draw_list, draw_order, frustum_planes, shadow_casters, static_objects
from diviewer.gl.resources import set_uniform
from diviewer.scene import camera as cam
from diviewer.scene.model import FrameConfig

_IDENTITY = np.identity(4)


def frame_draw_list(r, config: FrameConfig) -> tuple:
    """`culling.draw_list` of renderer ``r``'s scene per (scene, objects tuple), its boxes (N, 2, 3) and its
    alpha-masked items (N,); the static geometry uploaded (once per scene) where the frame holds it."""
    if r.draw_cache[0] is not r.scene or r.draw_cache[1] is not config.objects:
        static = static_objects(r.scene, config)
        if static is not None:
            r.gpu.set_static(r.ctx, r.scene.meshes, static, key=r.scene)
        items = draw_list(r.scene, config, r.gpu, static)
        boxes = np.array([it[3] for it in items], np.float64).reshape(-1, 2, 3)
        cut_out = np.array([r.scene.materials[it[1]].is_masked for it in items], bool)
        r.draw_cache = (r.scene, config.objects, (items, boxes, cut_out))
    return r.draw_cache[2]


def draw_objects(r, config: FrameConfig, file: str, defines: dict, uniforms: dict, view: np.ndarray | None,
                 clip: np.ndarray, stage: str, cull_back: bool = False, sweep: tuple | None = None,
                 previous_model=None) -> None:
    """Draw the frame's objects inside the frustum of ``clip`` (world to clip space) with shaders/<file>, renderer
    ``r``'s resources; alpha-masked materials use its ALPHA_TEST variant; ``cull_back``: single-sided materials
    without their back faces; ``sweep``: `shadow_casters`' arguments after the boxes, to draw only those. Counts
    draws and triangles (before face culling) in ``r.drawn[stage]``. The G-buffer flushes every ``r.flush_every``
    draws.

    ``uniforms`` (name -> value) are the pass's, set on each program variant before its first draw;
    ``previous_model(name, model)``, where given, gives each draw's ``m_prev_model`` (`MotionVectors.previous_model`).
    """
    progs: dict[bool, moderngl.Program] = {}
    items, boxes, cut_out = frame_draw_list(r, config)
    keep = boxes_visible(frustum_planes(clip), boxes) if r.culling else np.ones(len(items), bool)
    keep &= shadow_casters(boxes, *sweep) if sweep is not None else True
    draws, triangles = r.drawn.get(stage, (0, 0))
    triangles += sum(it[0].triangles for it, k in zip(items, keep) if k)
    r.drawn[stage] = (draws + int(keep.sum()), triangles)
    eye = cam.view_to_world(view)[:3, 3] if view is not None else None
    flush = gl_flush() if stage == "gbuffer" and r.flush_every > 0 else None  # shadows: no gain measured
    ctx, materials, gpu = r.ctx, r.scene.materials, r.gpu
    for n, i in enumerate(draw_order(boxes, keep, cut_out, eye)):
        if flush is not None and n and n % r.flush_every == 0:
            flush()
            r.flushes += 1
        gmesh, mat_name, model, _, name = items[i]
        mat = materials[mat_name]
        masked = mat.is_masked
        if cull_back:  # the other passes draw both faces: face culling is never on there
            (ctx.disable if mat.double_sided else ctx.enable)(moderngl.CULL_FACE)
        if masked not in progs:
            progs[masked] = r.shaders.program(file, {**defines, "ALPHA_TEST": 1} if masked else defines)
            for name, value in uniforms.items():
                set_uniform(progs[masked], name, value)
        prog = progs[masked]
        m = _IDENTITY if model is None else model
        # A mirroring pose (negative scale) flips the winding: keep its outside front-facing.
        ctx.front_face = "cw" if model is not None and np.linalg.det(model[:3, :3]) < 0 else "ccw"
        set_uniform(prog, "m_model", m)
        if previous_model is not None:
            set_uniform(prog, "m_prev_model", previous_model(name, m))
        tex = gpu.textures.get(mat_name)
        if view is not None:
            set_uniform(prog, "m_normal", cam.normal_matrix(view @ m))
            set_uniform(prog, "u_albedo", tuple(mat.albedo))
            set_uniform(prog, "u_emission", tuple(mat.emission))
            set_uniform(prog, "u_has_texture", tex is not None)
            glow = gpu.emission_textures.get(mat_name)
            set_uniform(prog, "u_has_emission_map", glow is not None)
            if glow is not None:
                glow.use(location=1)
                set_uniform(prog, "u_emission_map", 1)
        if tex is not None and (view is not None or masked):
            tex.use(location=0)
            set_uniform(prog, "u_albedo_map", 0)
        if masked:
            set_uniform(prog, "u_alpha_cutoff", float(mat.alpha_cutoff))
        gmesh.vao(prog).render(moderngl.TRIANGLES)
    ctx.front_face = "ccw"
    if cull_back:
        ctx.disable(moderngl.CULL_FACE)
