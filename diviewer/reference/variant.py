"""Which Mitsuba 3 variant renders: cuda_ad_rgb on a CUDA GPU, else llvm_ad_rgb where a working
libLLVM >= 16 is found, else scalar_rgb.

drjit aborts the process (it does not raise) when a backend cannot compile its kernels, so the CUDA
variant and a candidate libLLVM are first tried in a child process. The choice and its reason are kept
for the records.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys
from dataclasses import dataclass

from diviewer.errors import DiviewerError, missing_extra

VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
"""Variants this module uses, fastest first."""

_LIBLLVM_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
                 "/usr/local/lib", "/usr/lib/llvm-{v}/lib")
_LIBLLVM_NAMES = ("libLLVM-{v}.so", "libLLVM-{v}.so.1", "libLLVM.so.{v}", "libLLVM.so.{v}.*")
_LIBLLVM_VERSIONS = (19, 18, 17, 16)
_MIN_LLVM = 16
"""drjit's LLVM backend aborts the process (uncatchable) in code generation with the system's LLVM 15."""

_PROBE = """
import sys, numpy as np, mitsuba as mi
mi.set_variant(sys.argv[1])
s = mi.load_dict({'type': 'scene', 'integrator': {'type': 'path', 'max_depth': 3},
    'shape': {'type': 'sphere', 'bsdf': {'type': 'diffuse'}}, 'light': {'type': 'constant'},
    'sensor': {'type': 'perspective', 'to_world': mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
               'film': {'type': 'hdrfilm', 'width': 8, 'height': 8}}})
img = np.array(mi.render(s, spp=4, seed=0))
assert img.shape == (8, 8, 3) and np.all(np.isfinite(img)) and img.mean() > 0.1, img.mean()
print('ok')
"""


@dataclass(frozen=True)
class VariantInfo:
    """Which Mitsuba variant this process renders with, and why."""

    variant: str
    libllvm: str | None
    """The libLLVM the llvm variant uses (DRJIT_LIBLLVM_PATH), or None."""
    reason: str


_variant_info: VariantInfo | None = None


def import_mitsuba():
    """The mitsuba module, or the project error naming the extra that installs it."""
    try:
        import mitsuba  # noqa: PLC0415 (heavy optional dependency, imported where needed)
    except ImportError as exc:
        raise missing_extra("mitsuba") from exc
    return mitsuba


def _llvm_version(path: str) -> int | None:
    m = re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(os.path.realpath(path))) or \
        re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(path)) or re.search(r"llvm-(\d+)", path)
    return int(m.group(1)) if m else None


def find_libllvm() -> str | None:
    """A libLLVM newer than 15: DRJIT_LIBLLVM_PATH if set, else the newest in the usual Debian places."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env:
        return env if os.path.isfile(env) else None
    for v in _LIBLLVM_VERSIONS:
        for d in _LIBLLVM_DIRS:
            for n in _LIBLLVM_NAMES:
                hits = sorted(glob.glob(os.path.join(d.format(v=v), n.format(v=v))))
                if hits:
                    return hits[0]
    return None


def _probe(variant: str, env: dict[str, str], what: str, timeout: float = 180.0) -> str | None:
    """Render a tiny scene with ``variant`` in a child process; None if it works, else why not.

    A child process, because drjit aborts (not raises) when a backend cannot compile its kernels.
    """
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE, variant], env=env, capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"the {variant} test render {what} took more than {timeout:.0f} s"
    if r.returncode == 0 and r.stdout.strip().endswith("ok"):
        return None
    tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or [f"exit status {r.returncode}"]
    return f"the {variant} test render {what} failed ({tail[0][:200]})"


def _probe_llvm(path: str) -> str | None:
    """None if llvm_ad_rgb renders with the libLLVM at ``path``, else why not."""
    return _probe("llvm_ad_rgb", dict(os.environ, DRJIT_LIBLLVM_PATH=path), f"with {path}")


def select_variant(prefer: str | None = None) -> str:
    """Choose and set the Mitsuba variant for this process: the fastest that works here.

    Args:
        prefer: ``"cuda_ad_rgb"`` to use the GPU where this mitsuba build has the variant and a CUDA
            device renders (verified once per process in a child process), else what ``"llvm_ad_rgb"``
            gives; ``"scalar_rgb"`` to skip the JIT variants; ``"llvm_ad_rgb"`` to use it where a
            working libLLVM newer than 15 is found (DRJIT_LIBLLVM_PATH, else libLLVM-19/18/17/16 in the
            usual Debian places, which then goes into DRJIT_LIBLLVM_PATH). The libLLVM is verified once
            per process with a tiny render in a child process; scalar_rgb is the fallback. None: the
            environment variable DIVIEWER_MITSUBA_VARIANT if set (`--variant` on the command line sets
            it), else ``"cuda_ad_rgb"`` (which falls back as above on a machine without CUDA).

    Returns:
        The variant now set; ``variant_info()`` says which libLLVM and why.
    """
    global _variant_info, _llvm_result
    mi = import_mitsuba()
    source = "prefer" if prefer else "DIVIEWER_MITSUBA_VARIANT"
    prefer = prefer or os.environ.get("DIVIEWER_MITSUBA_VARIANT") or None
    if prefer is not None and prefer not in VARIANTS:
        raise DiviewerError(f"unknown Mitsuba variant '{prefer}'; use one of {', '.join(VARIANTS)}", field=source)
    if prefer == "scalar_rgb":
        info = VariantInfo("scalar_rgb", None, "scalar_rgb requested")
    else:
        info = _choose_cuda(mi) if prefer in (None, "cuda_ad_rgb") else None
        if info is None:
            if _llvm_result is None:
                _llvm_result = _choose_llvm(mi)
            info = _llvm_result
    mi.set_variant(info.variant)
    _variant_info = info
    return info.variant


_llvm_result: VariantInfo | None = None
_cuda_result: tuple[VariantInfo | None] | None = None


def _choose_cuda(mi) -> VariantInfo | None:
    """cuda_ad_rgb if this build has it and a CUDA device renders with it (probed once), else None."""
    global _cuda_result
    if _cuda_result is None:
        if "cuda_ad_rgb" not in mi.variants():
            _cuda_result = (None,)
        elif not _has_cuda_driver():
            _cuda_result = (None,)
        else:
            failure = _probe("cuda_ad_rgb", dict(os.environ), "on this machine's GPU")
            _cuda_result = (None,) if failure else (VariantInfo("cuda_ad_rgb", None, "verified on this machine's GPU"),)
    return _cuda_result[0]


def _has_cuda_driver() -> bool:
    """Whether a CUDA driver library is present at all (skips the child-process probe where it is not)."""
    return any(glob.glob(os.path.join(d, "libcuda.so*")) for d in
               ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
                "/usr/local/cuda/lib64", "/usr/local/nvidia/lib64"))


def _choose_llvm(mi) -> VariantInfo:
    if "llvm_ad_rgb" not in mi.variants():
        return VariantInfo("scalar_rgb", None, "this mitsuba build has no llvm_ad_rgb variant")
    path = find_libllvm()
    if path is None:
        where = os.environ.get("DRJIT_LIBLLVM_PATH")
        why = (f"DRJIT_LIBLLVM_PATH={where} is not a file" if where else
               f"no libLLVM {_MIN_LLVM} or newer found (Debian: apt-get install libllvm19)")
        return VariantInfo("scalar_rgb", None, why)
    version = _llvm_version(path)
    if version is not None and version < _MIN_LLVM:
        return VariantInfo("scalar_rgb", None, f"{path} is LLVM {version}; llvm_ad_rgb needs {_MIN_LLVM} or newer")
    failure = _probe_llvm(path)
    if failure is not None:
        return VariantInfo("scalar_rgb", None, failure)
    os.environ["DRJIT_LIBLLVM_PATH"] = path  # drjit reads it when its LLVM backend first starts
    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception as exc:  # drjit raises ImportError/RuntimeError when its LLVM backend cannot start
        return VariantInfo("scalar_rgb", None, f"llvm_ad_rgb failed to start in this process: {exc}")
    return VariantInfo("llvm_ad_rgb", path, f"verified with {path}")


def variant_info() -> VariantInfo:
    """The variant in use and why (chooses one with select_variant if none of ours is set)."""
    mi = import_mitsuba()
    v = mi.variant()
    if v not in VARIANTS:
        select_variant()
        v = mi.variant()
    if _variant_info is not None and _variant_info.variant == v:
        return _variant_info
    lib = os.environ.get("DRJIT_LIBLLVM_PATH") if v.startswith("llvm") else None
    return VariantInfo(v, lib, "set by the caller (mitsuba.set_variant)")


def current_variant(mi) -> str:
    """The variant set now; chooses one (select_variant) if none of ours is set."""
    v = mi.variant()
    if v not in VARIANTS:
        return select_variant()
    return v
