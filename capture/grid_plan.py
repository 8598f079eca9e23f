"""Grid plans: sweep plans whose camera and light poses follow a hemisphere layout.

The layouts are :func:`core.directions.hemisphere_layout`'s, the ones the simulator's fields use,
so :func:`grid_plan` captures on the simulated rig what ``rig sim field`` simulates; a plan file's
``layout`` + ``count`` poses (:mod:`capture.plan_file`) are :func:`layout_angles` too.
"""

from __future__ import annotations

from collections.abc import Sequence

from capture.plan import Angles, SweepPlan, check_plan_size
from core.directions import angles_deg_from_direction, hemisphere_layout
from core.errors import InputError

__all__ = ["LAYOUTS", "grid_plan", "layout_angles"]

#: Hemisphere layouts of :func:`core.directions.hemisphere_layout`.
LAYOUTS = ("grid", "fibonacci")


def layout_angles(count: int, layout: str) -> tuple[Angles, ...]:
    """``count`` (azimuth_deg, inclination_deg) over the upper hemisphere in ``layout``.

    The directions of :func:`core.directions.hemisphere_layout`, which the simulator's fields
    use too (``sim.field.field_cameras`` and the lights of ``sim.field.simulate_field``).
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise InputError(f"a layout needs a positive count, got {count!r}")
    azimuth, inclination = angles_deg_from_direction(hemisphere_layout(count, layout))
    return tuple((float(a), float(i)) for a, i in zip(azimuth, inclination, strict=True))


def grid_plan(
    cameras: int,
    lights: int,
    *,
    exposures_ms: Sequence[float] = (40.0,),
    layout: str = "grid",
    dark_frames: bool = True,
    ordering: str = "optimised",
) -> SweepPlan:
    """A plan of ``cameras`` x ``lights`` hemisphere poses, the layout of ``rig sim field``.

    Parameters
    ----------
    cameras, lights : int, pose counts
    exposures_ms : sequence of float, the bracket
    layout : {"grid", "fibonacci", "hemisphere"}, ``hemisphere`` meaning ``fibonacci`` (the
        near-uniform one)
    dark_frames, ordering : as :class:`SweepPlan`
    """
    check_plan_size(cameras, lights, f"a grid plan of {cameras} x {lights}")
    layout = "fibonacci" if layout == "hemisphere" else layout
    if layout not in LAYOUTS:
        raise InputError(f"unknown layout {layout!r}; use 'grid', 'fibonacci' or 'hemisphere'")
    return SweepPlan(
        cameras=layout_angles(cameras, layout),
        lights=layout_angles(lights, layout),
        exposures_ms=tuple(exposures_ms),
        dark_frames=dark_frames,
        ordering=ordering,
    )
