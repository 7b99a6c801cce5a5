"""One frame of a scene rendered headless into numpy arrays, for scripts (`diviewer.render_frame`): the GL buffers
`diviewer render` writes, and with a model its neural GI image, nothing written to disk."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer.frames import parse_resolution
from diviewer.scene import FrameConfig, Scene, load_scene


def render_frame(scene: str | Path | Scene, config: FrameConfig | None = None, size: int | str | tuple[int, int] = 256,
                 model: str | Path | None = None, provider: str | None = None) -> dict[str, np.ndarray]:
    """Render one configuration of ``scene`` in a headless GL context, as `diviewer render` does.

    Args:
        scene: a shipped scene's name, a scene file, or a loaded `Scene`.
        config: the frame's camera, lights and objects (`diviewer.scene.sample_config` draws one); None: the
            scene's default.
        size: N (square), "WxH" or (width, height).
        model: an ONNX model of the scene (`diviewer export`, or a shipped one: assets/models/SCENE.onnx): also
            run it on the frame (onnxruntime's ``provider``) and return its image as ``neural``.

    Returns:
        The named buffers, linear float32, top row first: ``depth`` (H, W); ``normal``, ``albedo``, ``direct``
        (H, W, 3) and the other inputs the model takes; ``neural`` (H, W, 3) with a model.

    Raises:
        DiviewerError: a scene or model that cannot be used, a size out of range, or a frame that came out with
            non-finite values.
    """
    from diviewer.gl.context import check_render_size, headless_context
    from diviewer.gl.renderer import BUFFERS, Renderer, RenderSettings
    from diviewer.render import check_finite, model_pass

    scene = scene if isinstance(scene, Scene) else load_scene(str(scene))
    width, height = parse_resolution("x".join(map(str, size)) if isinstance(size, tuple) else str(size), "size")
    config = scene.default if config is None else config
    net = None
    if model is not None:
        from diviewer.contract.runtime import NeuralGI

        net = NeuralGI(model, scene=scene, provider=provider)
        net.check_size(width, height)
    settings = RenderSettings().for_scene(scene)
    with headless_context() as ctx:
        check_render_size(ctx, width, height, "size")
        renderer = Renderer(ctx, scene, width, height, settings)
        neural = None
        try:
            frame = renderer.frame(config)
            if net is not None:
                neural = model_pass(ctx, scene, renderer, net, config)  # the renderer's buffers are read above
                frame["neural"] = neural.image()
            check_finite(scene, config, frame, (*BUFFERS, "neural"))
        finally:
            for resource in (neural, renderer):
                if resource is not None:
                    resource.release()
    return frame
