"""What training both relightable networks shares: device, threads, layers, codes, held-out lights.

PyTorch's device and threads, dense networks and their numpy layers, principal-component
starting codes, and held-out lights spread over the dome.

The learned rung (:mod:`processing.learned_rti_training`) and OpenLIME's neural model
(:mod:`processing.neural_rti_fit`) both train small dense networks with PyTorch and keep them
as numpy arrays; both start free codes at principal-component scores and hold out lights
spread over the dome. PyTorch is imported only inside these functions.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from core.directions import farthest_point_order
from core.errors import InputError
from processing.learned_rti import _encoder_input

if TYPE_CHECKING:  # imported when training: relighting never needs it
    import torch

__all__ = [
    "Device",
    "adam",
    "check_settings",
    "idle_cores",
    "numpy_layers",
    "principal_codes",
    "torch_mlp",
    "training_device",
    "validation_lights",
]

#: Where a network is trained: "auto" (CUDA when available), "cpu" or "cuda".
Device = Literal["auto", "cpu", "cuda"]


class _Settings(Protocol):
    """What both settings classes hold that :func:`check_settings` reads by name."""

    @property
    def lights_per_step(self) -> int | None: ...
    @property
    def threads(self) -> int | None: ...
    @property
    def device(self) -> str: ...


def check_settings(
    settings: _Settings,
    *,
    model: str,
    counts: tuple[str, ...],
    share: str,
    also: tuple[tuple[bool, str], ...] = (),
) -> None:
    """Refuse a network's training settings that no training could run (InputError).

    Both settings classes carry whole counts, ``lights_per_step`` and ``threads`` (a count or
    None), a share of lights held out and a device; ``also`` holds each class's own checks
    as (holds, message) pairs, tried between the counts and the share so that the first
    fault reported is the one each class reported before the checks were shared.

    Parameters
    ----------
    settings : the frozen settings (read by attribute name)
    model : the model's name in the messages ("learned", "neural")
    counts : attributes that must be at least 1
    share : the attribute holding the share of lights held out, in [0, 0.5)
    also : (holds, message) pairs: the first that does not hold is refused with its message
    """
    for name in counts:
        if getattr(settings, name) < 1:
            raise InputError(f"{model} model: {name} must be at least 1")
    for name, value in (
        ("lights_per_step", settings.lights_per_step),
        ("threads", settings.threads),
    ):
        if value is not None and value < 1:
            raise InputError(f"{model} model: {name} must be at least 1 (or None)")
    for holds, message in also:
        if not holds:
            raise InputError(f"{model} model: {message}")
    held_out = getattr(settings, share)
    if not 0.0 <= held_out < 0.5:
        raise InputError(
            f"{model} model: {share} is the share of lights held out, in [0, 0.5); got {held_out}"
        )
    if settings.device not in ("auto", "cpu", "cuda"):
        raise InputError(f"{model} model: device must be auto, cpu or cuda, not {settings.device}")


def validation_lights(
    directions: NDArray[np.floating], share: float, *, seed: int = 0
) -> NDArray[np.int64]:
    """Indices (sorted, int64) of about ``share`` of the T lights (T, 3), spread over the dome.

    Farthest-point picks: no two held-out lights are neighbours, so each leaves a gap about
    one light spacing wide, like the gaps between measured lights that relighting fills. At
    least 2 lights stay in and, when ``share`` > 0, at least 1 is held out.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    count = min(len(d) - 2, max(1, round(share * len(d)))) if share > 0 else 0
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    return np.sort(farthest_point_order(d, seed=seed)[:count])


def idle_cores() -> int:
    """Cores no other process keeps busy (1-minute load average), at least 1.

    PyTorch's CPU threads wait for each other at every layer: on cores other processes also
    use, two threads measured 6 to 9 times slower than one, while on idle cores one thread
    is at most twice as slow as two.
    """
    cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except OSError:  # not reported on this system
        return 1
    return max(1, min(cores, math.floor(cores - load)))


def training_device(asked: Device) -> str:
    """The device to train on: CUDA when asked for (refused when absent) or, for "auto", present."""
    import torch

    available = torch.cuda.is_available()
    if asked == "cuda" and not available:
        raise InputError("learned model: device 'cuda' asked for, but PyTorch sees no CUDA GPU")
    return "cuda" if asked == "cuda" or (asked == "auto" and available) else "cpu"


def principal_codes(encoded: NDArray[np.float32], k: int, seed: int) -> NDArray[np.float32]:
    """Starting free codes (N, k) float32: each sample's first k principal-component scores.

    Free codes move about one learning rate per pass, so from small random values they need
    a hundred passes to spread; the principal scores (of the encoded values, scaled to a
    standard deviation of 0.5 along the first component) already tell samples apart.
    """
    rows = _encoder_input(encoded).astype(np.float64)
    rng = np.random.default_rng(seed)
    basis_rows = rows[rng.permutation(len(rows))[:20000]]
    mean = basis_rows.mean(axis=0)
    _, _, vt = np.linalg.svd(basis_rows - mean, full_matrices=False)
    scores = np.zeros((len(rows), k))
    used = min(k, vt.shape[0])
    scores[:, :used] = (rows - mean) @ vt[:used].T
    spread = float(np.std(scores[:, 0])) if len(rows) > 1 else 0.0
    scores *= 0.5 / spread if spread > 0 else 1.0
    return scores.astype(np.float32)


def adam(parameters: Any) -> torch.optim.Adam:
    """PyTorch's Adam over ``parameters`` (tensors, or groups of them with their options).

    A first optimiser imports ``torch._dynamo``, whose import makes PyTorch's compiler cache
    folder in the temp folder (``torchinductor_<user>``) and leaves it there: every training
    left one behind, although nothing here compiles. Unless the user chose that folder
    (``TORCHINDUCTOR_CACHE_DIR``), the import makes it in a temporary folder removed at once.

    The update is PyTorch's fused one (one kernel over every parameter, on the CPU as on a
    GPU): the learned rung's codes are a parameter of a row per sample, updated every step
    although a step touches a few hundred rows, and the unfused update of 160,000 codes took
    twice as long as the rest of the step.
    """
    import torch

    if "torch._dynamo" not in sys.modules and "TORCHINDUCTOR_CACHE_DIR" not in os.environ:
        with tempfile.TemporaryDirectory(prefix="rig-torch-") as scratch:
            os.environ["TORCHINDUCTOR_CACHE_DIR"] = scratch
            try:
                import torch._dynamo
            finally:
                os.environ.pop("TORCHINDUCTOR_CACHE_DIR", None)
    return torch.optim.Adam(parameters, fused=True)


def torch_mlp(sizes: list[int]) -> torch.nn.Sequential:
    """Dense layers of ``sizes`` with ELU between them (none after the last)."""
    import torch

    layers: list[torch.nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ELU())
    return torch.nn.Sequential(*layers)


def numpy_layers(
    network: torch.nn.Sequential,
) -> tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...]:
    """The (weight (in, out), bias) pairs of the network's dense layers, as numpy arrays."""
    import torch

    return tuple(
        (
            np.ascontiguousarray(module.weight.detach().cpu().numpy().T, dtype=np.float32),
            module.bias.detach().cpu().numpy().astype(np.float32),
        )
        for module in network
        if isinstance(module, torch.nn.Linear)
    )
