"""The encodings of `diviewer.contract.encoding` on torch tensors: the same functions, given torch's operations.

`diviewer.contract.encoding` defines the curves once against a few array operations and never imports torch
(the viewer and the benchmark run without it); training and ONNX export call these wrappers, which
pass `TORCH_OPS`, so the exported graph carries exactly the encoding the runtime documents.
"""

from __future__ import annotations

from typing import Any

import torch

from diviewer.contract import encoding
from diviewer.contract.encoding import ArrayOps, Encoding


class TorchOps(ArrayOps):
    """`ArrayOps` on torch tensors (every op maps to one ONNX operator)."""

    abs = staticmethod(torch.abs)
    sign = staticmethod(torch.sign)
    log = staticmethod(torch.log)
    exp = staticmethod(torch.exp)
    isnan = staticmethod(torch.isnan)
    isinf = staticmethod(torch.isinf)

    @staticmethod
    def where(cond: Any, a: Any, b: Any) -> Any:
        return torch.where(cond, a, b)

    @staticmethod
    def clip(x: Any, lo: float, hi: float) -> Any:
        return x.clamp(lo, hi)

    @staticmethod
    def cat(parts: list[Any], axis: int) -> Any:
        return torch.cat(parts, dim=axis)

    @staticmethod
    def expand_dims(x: Any, axis: int) -> Any:
        return x.unsqueeze(axis)

    @staticmethod
    def prepare(x: Any, name: str) -> Any:
        """x as a float32-or-wider tensor; integer tensors are refused (their scale is unknown)."""
        if not isinstance(x, torch.Tensor):
            return torch.as_tensor(x, dtype=torch.float64)
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        return x.float() if x.element_size() < 4 else x  # float16/bfloat16 in, float32 math


TORCH_OPS = TorchOps()


def encode_radiance(x: torch.Tensor, enc: Encoding) -> torch.Tensor:
    """`diviewer.contract.encoding.encode_radiance` on a tensor."""
    return encoding.encode_radiance(x, enc, TORCH_OPS)


def decode_radiance(y: torch.Tensor, enc: Encoding) -> torch.Tensor:
    """`diviewer.contract.encoding.decode_radiance` on a tensor."""
    return encoding.decode_radiance(y, enc, TORCH_OPS)


def encode_inputs(depth: torch.Tensor, normal: torch.Tensor, albedo: torch.Tensor, direct: torch.Tensor,
                  enc: Encoding, *, channel_axis: int) -> torch.Tensor:
    """`diviewer.contract.encoding.encode_inputs` on tensors (NCHW batches: channel_axis=1)."""
    return encoding.encode_inputs(depth, normal, albedo, direct, enc, channel_axis=channel_axis, ops=TORCH_OPS)
