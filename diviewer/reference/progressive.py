"""The viewer's path-traced reference: Mitsuba renders the current view progressively on a worker thread.

Passes of 1, 2, 4, ... samples per pixel (capped per pass, so a change is picked up quickly), each
with its own seed, are averaged into one image weighted by their sample counts. When the frame
configuration changes the worker drops what it has and starts again; the frame loop only ever
calls ``request`` and ``latest``, which never wait for a render.
"""

from __future__ import annotations

import importlib.util
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene.model import FrameConfig, Scene


@dataclass(frozen=True)
class ReferenceSettings:
    """How the viewer's reference is rendered."""

    max_spp: int = 1024
    """Stop refining at this many samples per pixel."""
    first_spp: int = 1
    """Samples of the first pass (each later pass doubles, up to ``pass_spp``)."""
    pass_spp: int = 32
    """Most samples in one pass: bounds how long a change waits for the pass under way."""
    max_depth: int = 16
    """Path length limit (as the dataset's ground truth: diviewer.reference.mitsuba.DEFAULT_MAX_DEPTH)."""
    variant: str | None = None
    """Mitsuba variant: None picks llvm_ad_rgb where it works, else scalar_rgb."""
    threads: int | None = None
    """Render threads; None leaves one core to the frame loop (all cores minus one, at least one)."""


@dataclass(frozen=True)
class ReferenceImage:
    """The accumulated reference of one request: (H, W, 3) float32 linear radiance, top row first."""

    image: np.ndarray
    spp: int
    generation: int
    seconds: float
    """Time since the request, including loading the scene into Mitsuba."""
    serial: int
    """Increases with every published image (the app uploads when it changes)."""


def mitsuba_missing() -> str | None:
    """Why there can be no reference (Mitsuba not installed), or None."""
    if importlib.util.find_spec("mitsuba") is None:
        return ("the path-traced reference needs Mitsuba 3, which is not installed: "
                "pip install 'diviewer[train]' (or pip install mitsuba)")
    return None


class ProgressiveReference:
    """A worker thread that path-traces the requested (scene, configuration, size) ever more finely."""

    def __init__(self, settings: ReferenceSettings = ReferenceSettings()):
        self.settings = settings
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stop = False
        self._paused = True
        self._job: tuple | None = None
        self._generation = 0
        self._done_generation = -1
        self._latest: ReferenceImage | None = None
        self._serial = 0
        self.error: str | None = mitsuba_missing()
        """Why the reference cannot be rendered (Mitsuba missing, the scene not representable)."""
        self.variant: str | None = None
        self.started = 0.0

    @property
    def available(self) -> bool:
        return self.error is None

    def request(self, scene: Scene, config: FrameConfig, width: int, height: int) -> None:
        """Render this view (no-op when it is the one under way); starts the worker on first use."""
        key = (id(scene), config, int(width), int(height))
        with self._cond:
            self._paused = False
            if self._job is None or self._job[0] != key:
                self._job = (key, scene, config, int(width), int(height))
                self._generation += 1
                self.started = time.perf_counter()
                if isinstance(self.error, _JobError):
                    self.error = None
            self._cond.notify_all()
        if self._thread is None and mitsuba_missing() is None:
            self._thread = threading.Thread(target=self._run, name="diviewer-reference", daemon=True)
            self._thread.start()

    def pause(self) -> None:
        """Stop refining after the pass under way (the reference is not on screen); ``request`` resumes."""
        with self._cond:
            self._paused = True

    def latest(self) -> ReferenceImage | None:
        """The newest accumulated image of the current request, or None while its first pass runs."""
        with self._cond:
            if self._latest is not None and self._latest.generation == self._generation:
                return self._latest
            return None

    def status(self) -> str:
        """One line for the panel."""
        if self.error:
            return str(self.error)
        img = self.latest()
        if self._thread is None:
            return "idle"
        if img is None:
            return f"path tracing... ({time.perf_counter() - self.started:.1f} s, {self.variant or 'starting Mitsuba'})"
        done = " (done)" if self._done_generation == self._generation else ""
        return f"{img.spp} spp in {img.seconds:.1f} s{done} ({self.variant})"

    def close(self, timeout: float = 10.0) -> None:
        """Stop the worker (after the pass under way) and wait for it."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    # --- the worker -------------------------------------------------------------------------------
    def _current(self, generation: int) -> bool:
        return not self._stop and self._generation == generation

    def _run(self) -> None:
        from diviewer.reference import mitsuba as ref

        try:
            self.variant = ref.select_variant(self.settings.variant)
            import drjit as dr

            dr.set_thread_count(self.settings.threads or max(1, (os.cpu_count() or 2) - 1))
        except Exception as exc:  # a broken install: say so in the panel, never kill the viewer
            self.error = f"Mitsuba cannot start: {exc}"
            return
        s = self.settings
        while True:
            with self._cond:
                while not self._stop and (self._job is None or self._paused
                                          or self._done_generation == self._generation):
                    self._cond.wait()
                if self._stop:
                    return
                _, scene, config, width, height = self._job
                generation = self._generation
            t0 = self.started
            try:
                frame = ref.load_frame(scene, config, width, height)
            except DiviewerError as exc:
                with self._cond:
                    self.error = _JobError(f"the reference cannot render this frame: {exc}")
                    self._done_generation = generation
                continue
            acc, total, spp, seed = None, 0, s.first_spp, 0
            while total < s.max_spp:
                with self._cond:
                    while self._paused and self._current(generation):
                        self._cond.wait()
                    if not self._current(generation):
                        break
                img = frame.full_light(spp, seed, s.max_depth)  # the truth's estimator (one pass where it can)
                if not np.all(np.isfinite(img)):
                    img = np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)
                acc = img if acc is None else acc + (img - acc) * (spp / (total + spp))
                total += spp
                with self._cond:
                    if not self._current(generation):
                        break
                    self._serial += 1
                    self._latest = ReferenceImage(np.ascontiguousarray(acc, dtype=np.float32), total, generation,
                                                  time.perf_counter() - t0, self._serial)
                seed += 1
                spp = max(1, min(spp * 2, s.pass_spp, s.max_spp - total))
            else:
                with self._cond:
                    if self._generation == generation:
                        self._done_generation = generation


class _JobError(str):
    """An error of one request (cleared by the next request), as opposed to Mitsuba being unusable."""
