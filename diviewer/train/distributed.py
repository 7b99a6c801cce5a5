"""Where and how the training processes run: the device, the process group under torchrun, the
data order (a pure function of seed and epoch), the loader, every process's random state, and the
stop flag set by Ctrl-C or SIGTERM that all ranks agree on."""

from __future__ import annotations

import os
import random
import signal
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.train.config import TrainConfig


@dataclass(frozen=True)
class Dist:
    """Where this process runs: rank and world size (1 without torchrun) and its device."""

    rank: int
    world: int
    device: Any
    initialized_here: bool

    @property
    def main(self) -> bool:
        return self.rank == 0


def cuda_device_count() -> int:
    """The CUDA devices torch sees here (0 where CUDA is not available)."""
    import torch

    return torch.cuda.device_count() if torch.cuda.is_available() else 0


def setup(cfg: TrainConfig) -> Dist:
    """Pick the device; under torchrun (WORLD_SIZE > 1) join the process group (NCCL on GPUs, else gloo)."""
    import torch
    import torch.distributed as dist

    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    want = cfg.device
    if want == "auto":
        want = "cuda" if torch.cuda.is_available() else "cpu"
    if want.startswith("cuda") and not torch.cuda.is_available():
        raise DiviewerError("CUDA is not available on this machine; use --device cpu (or auto)", field="--device")
    if world > 1:
        device = torch.device("cuda", local_rank) if want.startswith("cuda") else torch.device("cpu")
    else:  # an index always: torch.cuda.set_device and the CUDA RNG state refuse a bare "cuda"
        device = torch.device("cuda", 0) if want == "cuda" else torch.device(want)
    if device.type == "cuda":
        torch.cuda.set_device(device)
        torch.backends.cudnn.benchmark = True  # fixed input size: let cuDNN pick the fastest convolutions
    initialized = False
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
        initialized = True
    return Dist(rank=rank, world=world, device=device, initialized_here=initialized)


def epoch_batches(n: int, epoch: int, seed: int, batch_size: int, rank: int = 0, world: int = 1) -> list[list[int]]:
    """This process's batches (indices into the train split) for one epoch: a pure function of its args.

    The order is DistributedSampler's (shuffled by seed + epoch, padded so every rank gets as many
    batches), so a resumed run only needs (epoch, batch) to continue the same order.
    """
    from torch.utils.data import DistributedSampler

    sampler = DistributedSampler(range(n), num_replicas=world, rank=rank, shuffle=True, seed=seed, drop_last=False)
    sampler.set_epoch(epoch)
    order = list(sampler)
    return [order[i:i + batch_size] for i in range(0, len(order), batch_size)]


class InRam:
    """DataLoader dataset over the in-RAM split: one item is a whole batch, still float16."""

    def __init__(self, array: np.ndarray):
        self.array = array

    def __len__(self) -> int:
        return len(self.array)

    def __getitem__(self, idx: list[int]):
        import torch

        return torch.from_numpy(np.ascontiguousarray(self.array[idx]))


def loader(array: np.ndarray, batches: list[list[int]], cfg: TrainConfig, dev: Dist):
    import torch
    from torch.utils.data import DataLoader

    # batch_size=None: each sampler item is a list of indices and the dataset returns the batch.
    # The loader gets its own generator: by default it draws a worker seed from the global RNG,
    # which would shift dropout's random stream after a resume.
    return DataLoader(InRam(array), sampler=batches, batch_size=None, num_workers=cfg.num_workers,
                      pin_memory=dev.device.type == "cuda", generator=torch.Generator().manual_seed(cfg.seed))


def rng_state(device) -> dict[str, Any]:
    """This process's random state as tensors, lists and numbers (loadable with weights_only)."""
    import torch

    np_kind, np_keys, np_pos, np_has_gauss, np_gauss = np.random.get_state()
    py_version, py_state, py_gauss = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
        "numpy": {"kind": str(np_kind), "keys": [int(k) for k in np_keys], "pos": int(np_pos),
                  "has_gauss": int(np_has_gauss), "cached_gaussian": float(np_gauss)},
        "python": {"version": py_version, "state": list(py_state), "gauss_next": py_gauss},
    }


def set_rng_state(state: Mapping[str, Any], device) -> None:
    import torch

    torch.set_rng_state(state["torch"])
    if device.type == "cuda" and state.get("cuda") is not None:
        torch.cuda.set_rng_state(state["cuda"], device)
    n = state["numpy"]
    np.random.set_state((n["kind"], np.asarray(n["keys"], dtype=np.uint32), n["pos"], n["has_gauss"],
                         n["cached_gaussian"]))
    p = state["python"]
    random.setstate((p["version"], tuple(p["state"]), p["gauss_next"]))


def seed_all(seed: int) -> None:
    import torch

    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)


# ---------------------------------------------------------------------------------------------
# Checkpoints


def agree_max(value: int, dev: Dist) -> int:
    """The largest of every rank's value (rank 0 alone decides some things, e.g. early stopping)."""
    if dev.world == 1:
        return value
    import torch
    import torch.distributed as dist

    t = torch.tensor([float(value)], device=dev.device)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return int(t.item())


def stop_requested(flag: dict[str, bool], dev: Dist) -> bool:
    """Whether any process was asked to stop; every rank must agree, or the next collective hangs."""
    return bool(agree_max(int(flag["stop"]), dev))


def install_stop_handlers(flag: dict[str, bool], log: Callable[[str], None]) -> Callable[[], None]:
    """First SIGINT/SIGTERM: finish the step, save last.ckpt, stop. A second SIGINT stops at once."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum, frame):
        if flag["stop"] and signum == signal.SIGINT:
            raise KeyboardInterrupt
        flag["stop"] = True
        log(f"\n{signal.Signals(signum).name}: stopping after this step and saving last.ckpt "
            "(Ctrl-C again to stop at once)")

    for s in old:
        signal.signal(s, handler)
    return lambda: [signal.signal(s, h) for s, h in old.items()]
