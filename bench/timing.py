"""How the benchmarks time: medians after a warm-up, the interactive loop, the bandwidth floor.

:func:`median_ms` times repeated calls after one warm-up call (numba compiles on a first call);
:func:`loop_ms` times an engine's interactive loop (a new lighting, a new view, each rendered);
:func:`copy_bandwidth` is the memory bandwidth a large copy reaches, the floor of a frame that
reads its data once.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from core.camera_model import PinholeCamera
from processing.panorama import Panorama
from render.engines.modes import RelightEngine

__all__ = ["copy_bandwidth", "loop_ms", "median_ms"]


def median_ms(run: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``run()`` over ``repeats`` calls after one warm-up call, in ms."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3


def copy_bandwidth() -> float:
    """Bytes per second moved by a large copy (read + write)."""
    source = np.ones(50_000_000, dtype=np.float32)
    target = np.empty_like(source)
    ms = median_ms(lambda: np.copyto(target, source), 5)
    return 2 * source.nbytes / (ms * 1e-3)


def loop_ms(
    relighter: RelightEngine,
    panorama: Panorama,
    repeats: int,
    camera: PinholeCamera | None = None,
) -> dict[str, float]:
    """The interactive loop: a new lighting (rotated environment), or a new view, and render.

    New views turn ``camera`` (default a 512 x 512 view at 50 degrees inclination) in azimuth;
    a given ``camera`` is also the view of the new lightings (else the engine's current view).
    """
    template = camera if camera is not None else PinholeCamera(0.0, 50.0)
    if camera is not None:
        relighter.set_view(camera)
    yaws = iter(np.linspace(0.0, 360.0, 1000))
    azimuths = iter(np.linspace(0.0, 360.0, 1000))

    def new_lighting() -> None:
        relighter.set_lighting(panorama, yaw_deg=float(next(yaws)))
        relighter.render()

    def new_view() -> None:
        relighter.set_view(replace(template, azimuth_deg=float(next(azimuths))))
        relighter.render()

    return {
        "loop_new_lighting_ms": median_ms(new_lighting, repeats),
        "loop_new_view_ms": median_ms(new_view, repeats),
    }
