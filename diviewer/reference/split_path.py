"""One path-traced pass that returns a frame's full light and its direct part together.

A capture's ground truth is two images of each frame: the full path tracer (``pt``) and the same estimator cut to
paths of length 2 (``pt_direct``, `mitsuba.path_integrator` with ``max_depth = 2``). Rendered as two passes with one
seed, their first bounces draw the same random numbers, so ``indirect = pt - pt_direct`` carries none of the direct
light's noise; but the second pass traces every first bounce again (on Sponza at 228x128, 64 spp, a fifth of the
pair's time).

``split_path`` traces each path once and adds what its first vertex gathers from the lights to an AOV as well as to
the image: the direct light is then the first bounce of the very paths the full image sums, and ``full - direct`` is
their later bounces, exactly. It is the same estimator as ``path`` / ``volpath`` for what the project's scenes hold:
- diffuse (two-sided) surfaces, and ``mask`` cut-outs, which a path crosses with probability 1 - opacity without
  counting a bounce (volpath's null interaction; the masks are binary, so the crossing is decided, not drawn);
- delta lights (directional and point) sampled at every vertex, their shadow rays passing cut-out texels;
- Russian roulette from ``rr_depth`` on, as Mitsuba's (survival max(throughput), at most 0.95).
Lights with area (emissive surfaces, the ``constant`` sky) need multiple importance sampling, which it does not do:
`supports` says whether a frame can take it, and callers render those frames in two passes. Measured against the two
passes on Sponza (`split_path_check.py`, docs/architecture.md, docs/experiments.md): the same frame means within
the seeds' spread, as noisy, and 45 % less time.
"""

from __future__ import annotations

ONE_PASS, TWO_PASSES = "one_pass", "two_passes"
ESTIMATORS = (ONE_PASS, TWO_PASSES)
"""How a frame's ``pt`` and ``pt_direct`` are rendered: this integrator, or ``path`` twice (full, then
``max_depth = 2``) with one seed. A manifest without the record is of the second kind."""
NAME = "diviewer_split_path"
"""The integrator's Mitsuba plugin name."""
AOV = ("direct.R", "direct.G", "direct.B")
"""The film channels of the direct light, after the image's R, G, B."""

_classes: dict = {}
"""The integrator class per Mitsuba variant (Mitsuba's types are per variant), made and registered on first use."""
mi = dr = None
"""The mitsuba and drjit modules, bound on first use (``@dr.syntax`` re-runs the methods' source in this module's
namespace, so they must be module names, not a closure's; importing this module imports neither)."""


def supports(scene, config) -> bool:
    """Whether the frame's lights are all delta lights: no object of it wears an emissive material, no sky."""
    return max(scene.ambient) <= 0.0 and not any(scene.materials[o.material].is_emissive for o in config.objects)


def integrator_dict(mitsuba, max_depth: int, rr_depth: int) -> dict:
    """The ``mi.load_dict`` dict of the integrator, registered for the current variant first."""
    register(mitsuba)
    return {"type": NAME, "max_depth": int(max_depth), "rr_depth": int(rr_depth)}


def register(mitsuba) -> None:
    """Register the plugin with Mitsuba's current variant (once per variant)."""
    variant = mitsuba.variant()
    if variant not in _classes:
        cls = _classes[variant] = _define(mitsuba)
        mitsuba.register_integrator(NAME, lambda props: cls(props))


def _define(mitsuba):
    global mi, dr
    import drjit

    mi, dr = mitsuba, drjit

    class SplitPath(mi.SamplingIntegrator):
        """Full light as the image, its first bounce's light as three AOV channels (`AOV`)."""

        def __init__(self, props):
            super().__init__(props)
            self.max_depth = int(props.get("max_depth", 16))
            self.rr_depth = int(props.get("rr_depth", 5))
            if self.max_depth < 2 or self.rr_depth < 1:
                raise ValueError(f"max_depth must be >= 2 and rr_depth >= 1, got {self.max_depth}, {self.rr_depth}")

        def aov_names(self):
            return list(AOV)

        def to_string(self):
            return f"SplitPath[max_depth={self.max_depth}, rr_depth={self.rr_depth}]"

        @dr.syntax
        def visibility(self, scene, si, ds, active):
            """The light's transmittance from ``si`` to the sampled point ``ds.p``: 0 behind an opaque surface,
            1 where only cut-out texels lie between (their 1 - opacity multiplied in)."""
            tr = mi.Spectrum(1.0)
            ray = si.spawn_ray_to(ds.p)
            go = mi.Bool(active)
            while dr.hint(go, label="split_path_shadow"):
                hit = scene.ray_intersect(ray, go)
                blocked = go & hit.is_valid()
                tr[blocked] *= hit.bsdf(ray).eval_null_transmission(hit, blocked)
                go = blocked & (dr.max(tr) > 0.0)
                ray[go] = hit.spawn_ray_to(ds.p)
            return tr

        @dr.syntax
        def sample(self, scene, sampler, ray, medium=None, active=True):
            ctx = mi.BSDFContext()
            L, Ld, beta = mi.Spectrum(0.0), mi.Spectrum(0.0), mi.Spectrum(1.0)
            depth = mi.UInt32(0)  # scattering vertices before this one (a cut-out crossing is not one)
            ray, active, valid = mi.Ray3f(ray), mi.Bool(active), mi.Bool(False)
            while dr.hint(active, label="split_path"):
                si = scene.ray_intersect(ray, active)
                hit = active & si.is_valid()
                valid |= hit & (depth == 0)
                bsdf = si.bsdf(ray)
                # a cut-out texel: the path goes on through it, as volpath's null interaction
                null_tr = bsdf.eval_null_transmission(si, hit)
                p_null = dr.mean(null_tr)
                through = hit & (sampler.next_1d(hit) < p_null)
                scatter = hit & ~through
                beta[through] *= null_tr / dr.maximum(p_null, 1e-30)
                # the lights, sampled at this vertex (delta lights: no MIS), as path's emitter sampling
                nee = scatter & (depth + 1 < self.max_depth) & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(nee), False, nee)
                nee &= ds.pdf != 0.0
                tr = self.visibility(scene, si, ds, nee)
                f = bsdf.eval(ctx, si, si.to_local(ds.d), nee)
                gathered = dr.select(nee, beta * f * em_weight * tr, 0.0)
                L += gathered
                Ld += dr.select(depth == 0, gathered, 0.0)
                # the next direction, then Russian roulette as path's
                bs, weight = bsdf.sample(ctx, si, sampler.next_1d(scatter), sampler.next_2d(scatter), scatter)
                beta[scatter] *= weight
                depth[scatter] += 1
                rr = scatter & (depth >= self.rr_depth)
                q = dr.minimum(dr.max(beta), 0.95)
                survive = sampler.next_1d(rr) < q
                beta[rr] *= dr.rcp(q)
                go_on = scatter & (~rr | survive) & (depth + 1 < self.max_depth) & (dr.max(beta) > 0.0)
                ray[scatter] = si.spawn_ray(si.to_world(bs.wo))
                ray[through] = si.spawn_ray(ray.d)
                active = through | go_on
            return L, valid, [Ld.x, Ld.y, Ld.z]

    return SplitPath
