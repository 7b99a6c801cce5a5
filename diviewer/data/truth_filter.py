"""A path-traced truth's indirect light filtered over each surface: ``diviewer data filter-truth``.

A capture's ground truth at s spp carries Monte-Carlo noise that falls only as 1 / s; Sponza's 256-spp truth stands
a median 2.4-4.4 dB above the error of the model trained on it, where 6 dB is the aim (docs/sponza.md at commit c48f1bc). Each
doubling of the samples buys 3 dB for the whole capture's time again. Filtering the truth's indirect light over the
surface each pixel sees buys more for seconds: measured on the compact Sponza set against two 1024-spp renders
(`tools/experiments/filtered_truth_margin.py`), one level of this filter raised the 256-spp truth's margin over the
shipped model by 4.8-8.6 dB per split, bias included (docs/sponza.md at commit c48f1bc, "A filtered truth").

The filter (an edge-avoiding a-trous wavelet pass, as in Dammertz et al. 2010, with geometry alone as its guide):
- it filters the irradiance the network is trained on, ``E = (pt - pt_direct) / max(albedo, ALBEDO_FLOOR)``
  (`diviewer.train.targets`; the floor is `diviewer.data.scales`'), never the direct light nor the albedo's texture, and writes
  ``pt = pt_direct + max(albedo, ALBEDO_FLOOR) E'``, so ``pt_direct`` and every input stay as captured;
- each level is a 5x5 B3-spline kernel with holes (step 1, 2, 4, ... pixels); a neighbour's weight is the kernel's
  times ``max(0, n . n')^normal_power`` (view-space normals) times ``exp(-(d / plane)^2)``, where ``d`` is the
  neighbour's distance from the pixel's tangent plane over the pixel's depth: a neighbour on another surface, or
  across a crease or a step, counts little or nothing;
- pixels without geometry (depth 0) neither give nor take;
- with ``range_sigma`` > 0, a range term as joint bilateral filters have: the guide is ``E`` filtered by one level of
  geometry alone, and a neighbour's weight is multiplied by ``exp(-(dg / (range_sigma x mean g + RANGE_FLOOR))^2)``,
  ``dg`` the guides' luminance difference: an edge of the light itself within a surface (a contact shadow of the
  indirect light, the edge of a bounce's patch) counts little.
Without the range term it does not look at the noisy light itself: its bias is a blur of the irradiance within a
surface. Either way the margin's measurement counts that bias (a filtered truth's error against the converged image
is its noise and its bias together).

The filtered dataset is written into a new folder, as `diviewer.data.refine` does: its manifest is the source's
with a ``truth_filter`` record (the settings, the source's hash), part of the dataset's identity, and
``truth_filter_from`` (its folder), and its ``lineage`` adds this step to the source's. The source is verified first,
as `diviewer data check` does, and an evaluation set refused (`diviewer.data.lineage`). Seconds for a whole capture;
resumable; the source is never changed.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from diviewer.data.scales import floored_albedo
from diviewer.errors import DiviewerError

KERNEL = np.array([1.0, 4.0, 6.0, 4.0, 1.0], dtype=np.float32) / 16.0
"""The B3-spline taps of one level (per axis)."""
HOW = ("a-trous over E = (pt - pt_direct) / max(albedo, floor): 5x5 B3 taps at step 2^level, weight x max(0, n.n')^p "
       "x exp(-(plane distance / depth / plane)^2); pt = pt_direct + max(albedo, floor) E'")
"""The record's words for what was done (the manifest's ``truth_filter.how``)."""
HOW_RANGE = ("; with range_sigma, weight x exp(-(dg / (range_sigma mean(g) + floor))^2), g the luminance of E "
             "filtered by one level of geometry alone")
"""Added to `HOW` for a filter with a range term."""
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
"""Rec. 709 luminance weights: the guide's channels to one."""
RANGE_FLOOR = 1e-4
"""Added to the range term's scale (irradiance, linear): in light this dark the range term fades and geometry alone
decides."""


@dataclass(frozen=True)
class TruthFilter:
    """The filter's settings (a recipe's ``[capture] truth_filter`` table; `diviewer data filter-truth`'s options)."""

    levels: int = 1
    """A-trous levels (1: the 5x5 neighbourhood; each more doubles the reach)."""
    normal_power: float = 32.0
    """Exponent of the normals' cosine: 32 halves a neighbour's weight at 12 degrees."""
    plane: float = 0.01
    """Distance from the pixel's tangent plane, over its depth, at which a neighbour's weight falls to 1/e."""
    range_sigma: float = 0.0
    """The range term's width: the guides' luminance difference, over their mean, at which a neighbour's weight
    falls to 1/e; 0: no range term (geometry alone)."""

    def check(self, where: str = "truth_filter", options: bool = False) -> TruthFilter:
        """Refuse a setting out of range, naming it as ``where.name`` (a recipe's table), or with ``options`` as the
        command's option (``--normal-power``)."""
        field = (lambda name: "--" + name.replace("_", "-")) if options else (lambda name: f"{where}.{name}")
        if not (isinstance(self.levels, int) and not isinstance(self.levels, bool) and 1 <= self.levels <= 5):
            raise DiviewerError(f"levels must be an integer from 1 to 5, got {self.levels!r}", field=field("levels"))
        for name, lo in (("normal_power", 0.0), ("plane", 1e-6), ("range_sigma", 0.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < lo:
                raise DiviewerError(f"{name} must be a finite number of at least {lo:g}, got {v!r}", field=field(name))
        return self

    @classmethod
    def from_dict(cls, data, where: str = "truth_filter") -> TruthFilter:
        if not isinstance(data, dict):
            raise DiviewerError(f"must be a table ({', '.join(FIELDS)}), got {data!r}", field=where)
        unknown = sorted(set(data) - set(FIELDS))
        if unknown:
            raise DiviewerError(f"unknown field(s) {', '.join(unknown)} ({', '.join(FIELDS)})", field=where)
        return cls(**data).check(where)

    def record(self) -> dict:
        """The settings as a recipe's table; ``range_sigma`` only where there is a range term, so the records of
        the filters before it (and their datasets' identities) read as they did."""
        rec = asdict(self)
        if not self.range_sigma:
            del rec["range_sigma"]
        return rec


FIELDS = ("levels", "normal_power", "plane", "range_sigma")
"""A truth_filter table's fields."""


def view_positions(depth: np.ndarray, fov_y_deg: float) -> np.ndarray:
    """(H, W, 3) view-space positions of the pixels' centres from the G-buffer's depth (view-space -z)."""
    from diviewer.scene.camera import pixel_rays_view

    h, w = depth.shape
    rays = pixel_rays_view(w, h, fov_y_deg).astype(np.float64)
    return (rays / -rays[..., 2:3] * depth[..., None]).astype(np.float32)


def filter_irradiance(e: np.ndarray, normal: np.ndarray, depth: np.ndarray, fov_y_deg: float,
                      settings: TruthFilter = TruthFilter()) -> np.ndarray:
    """``e`` (H, W, C) filtered over the surfaces the G-buffer (view-space ``normal``, ``depth``) shows. A texel whose
    light, normal or depth is not finite, or that has no geometry, gives nothing to its neighbours and keeps its own
    value; every other output is a convex mix of finite inputs."""
    guide = None
    if settings.range_sigma > 0.0:
        one = TruthFilter(1, settings.normal_power, settings.plane)
        guide = np.nan_to_num(np.maximum(filter_irradiance(e, normal, depth, fov_y_deg, one) @ LUMINANCE, 0.0),
                              nan=0.0, posinf=0.0)  # a broken texel's guide: it gives nothing in any case
        guide = guide.astype(np.float64)  # the range term's scale (range_sigma x light) overflows float32 first
    n = np.nan_to_num(normal.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    hit = (depth > 0.0) & np.isfinite(depth) & np.all(np.isfinite(e), axis=-1) & np.any(n != 0.0, axis=-1)
    pos = view_positions(np.where(hit, depth, 0.0), fov_y_deg)
    inv_z = np.where(hit, 1.0 / np.maximum(depth, 1e-6), 0.0).astype(np.float32)
    out = np.where(hit[..., None], e, 0.0).astype(np.float32)
    h, w = hit.shape
    # The settings as the weights use them, each finite in float32 whatever the setting: a power beyond float32's
    # largest weighs as that one does (a cosine below 1 to it is 0), a plane beyond 1e30 has no plane term left,
    # a range term beyond 1e30 weighs every neighbour 1 (its relative difference is at most 2 / range_sigma).
    power = np.float32(min(settings.normal_power, float(np.finfo(np.float32).max)))
    inv_plane = np.float32(1.0 / settings.plane) if settings.plane < 1e30 else np.float32(0.0)
    sigma = min(settings.range_sigma, 1e30)
    for level in range(settings.levels):
        step = 1 << level
        r = 2 * step
        pad = lambda a: np.pad(a, [(r, r), (r, r)] + [(0, 0)] * (a.ndim - 2))  # noqa: E731
        pe, pn, pp, ph = pad(out), pad(n), pad(pos), pad(hit)
        pg = pad(guide) if guide is not None else None
        acc = np.zeros_like(out)
        wsum = np.zeros((h, w), np.float32)
        for a, ky in enumerate(KERNEL):
            for b, kx in enumerate(KERNEL):
                y, x = r + (a - 2) * step, r + (b - 2) * step
                nq, pq = pn[y:y + h, x:x + w], pp[y:y + h, x:x + w]
                # A cosine in [0, 1] (stored normals are a little off unit length) raised to any finite power
                # stays in [0, 1]: a weight never overflows, whatever normal_power is.
                cos = np.clip(np.sum(n * nq, axis=-1), 0.0, 1.0)
                d = np.abs(np.sum(n * (pq - pos), axis=-1)) * inv_z * inv_plane
                wq = (ky * kx) * ph[y:y + h, x:x + w] * cos ** power * np.exp(-d * d)
                if pg is not None:
                    gq = pg[y:y + h, x:x + w]
                    rel = (gq - guide) / (sigma * 0.5 * (gq + guide) + RANGE_FLOOR)
                    wq = wq * np.exp(-rel * rel).astype(np.float32)
                wq = np.where(np.isfinite(wq), wq, 0.0).astype(np.float32)  # a weight that cannot be had counts 0
                acc += wq[..., None] * pe[y:y + h, x:x + w]
                wsum += wq
        done = hit & (wsum > 0.0)
        out = np.where(done[..., None], acc / np.maximum(wsum, 1e-30)[..., None], out)
    return np.where(hit[..., None], out, e.astype(np.float32))


def filter_truth(pt: np.ndarray, pt_direct: np.ndarray, albedo: np.ndarray, normal: np.ndarray, depth: np.ndarray,
                 fov_y_deg: float, settings: TruthFilter = TruthFilter()) -> np.ndarray:
    """The full image with its indirect light filtered (`filter_irradiance` on the albedo-divided indirect light);
    ``pt_direct`` as it was. Pixels without geometry keep ``pt``."""
    a = floored_albedo(np.asarray(albedo, np.float32)).astype(np.float32)
    e = (pt.astype(np.float32) - pt_direct.astype(np.float32)) / a
    filtered = pt_direct.astype(np.float32) + a * filter_irradiance(e, normal, depth, fov_y_deg, settings)
    return np.where((depth > 0.0)[..., None], filtered, pt.astype(np.float32))


def truth_filter_manifest(src, settings: TruthFilter) -> dict:
    """The source's manifest with the ``truth_filter`` record and the step in its ``lineage`` (refused for a truth
    filtered already, or not path traced)."""
    from diviewer.data.lineage import with_step

    m = json.loads(json.dumps(src.manifest))
    where = src.root / "manifest.json"
    if m.get("gt") != "pt":
        raise DiviewerError(f"only a path-traced truth is filtered (its ground truth is '{m.get('gt')}')", path=where,
                            field="gt")
    if "truth_filter" in m:
        raise DiviewerError(f"its truth is filtered already; filter the dataset it came from "
                            f"({m.get('truth_filter_from')})", path=where, field="truth_filter")
    missing = [c for c in ("pt", "pt_direct", "albedo", "normal", "depth") if c not in src.slices]
    if missing:
        raise DiviewerError(f"the dataset has no {', '.join(missing)} channel", path=where, field="channels")
    m["truth_filter"] = {**settings.record(), "from_hash": src.hash,
                         "how": HOW + (HOW_RANGE if settings.range_sigma else "")}
    m["truth_filter_from"] = str(src.root)
    return with_step(src, m, "filter-truth", settings.record())


def filter_dataset(src_dir: Path, out: Path, settings: TruthFilter = TruthFilter(), log=print,
                   partial: bool = False) -> dict:
    """Write ``src_dir``'s frames (verified first; ``partial``: an incomplete source's present ones) with their truth
    filtered into ``out``; returns a summary (``filtered``: the frames written now)."""
    from diviewer.data.lineage import derivation_source, verified_frames
    from diviewer.data.refine import derive_frames, source_scene
    from diviewer.scene.loader import config_from_dict

    settings.check(options=True)
    src = derivation_source(src_dir, out, "filter-truth")
    manifest = truth_filter_manifest(src, settings)
    frames = verified_frames(src, "filter-truth", partial, log)
    scene = source_scene(src, manifest, "filter")
    sl = src.slices

    def per_frame(f: dict, arr: np.ndarray) -> tuple[str, dict]:
        c = {k: arr[..., sl[k]].astype(np.float32) for k in ("pt", "pt_direct", "albedo", "normal", "depth")}
        fov = config_from_dict(scene, f["config"]).camera.fov
        pt = filter_truth(c["pt"], c["pt_direct"], c["albedo"], c["normal"], c["depth"][..., 0], fov,
                          settings).astype(arr.dtype)
        if not np.all(np.isfinite(pt)):  # never written: a frame of a dataset is finite (`diviewer data check`)
            raise DiviewerError(f"frame {f['index']}: the filtered truth holds non-finite values (beyond "
                                f"{arr.dtype}'s range?); nothing was written for it", path=src.path(f["index"]),
                                field="pt")
        arr[..., sl["pt"]] = pt
        return "truth_filter", settings.record()

    what = (f"filter ({settings.levels} level(s), normal power {settings.normal_power:g}, plane {settings.plane:g}"
            + (f", range {settings.range_sigma:g})" if settings.range_sigma else ")"))
    return derive_frames(src, frames, out, manifest, "filter-truth", what, per_frame, tally="filtered", log=log)
