"""Splits of one capture's lights into the lights a method may use and the lights it must predict.

Shared by the held-out evaluation (:mod:`render.evaluation`) and the choices of the default
rung (:mod:`render.rung_choice`, :mod:`render.environment_choice`).

``every-other``
    test every second light in the field's order (the fit lights surround each test light);
``rings``
    the lights grouped into rings of equal inclination (in the camera frame for pixel fields),
    test every second ring: a harder gap, a whole ring unseen;
``random``
    half the lights at random (``random:SEED`` picks the seed; default 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.camera_model import rig_to_camera
from core.directions import spread_partition
from core.errors import InputError
from core.field_store import ReflectanceField

__all__ = [
    "RING_GAP_DEG",
    "SPLITS",
    "lowest_lights",
    "ring_groups",
    "split_lights",
    "spread_groups",
]

#: Ways :func:`split_lights` splits one capture.
SPLITS = ("every-other", "rings", "random")
#: Inclinations closer than this (degrees) belong to one ring.
RING_GAP_DEG = 2.0


def ring_groups(field: ReflectanceField) -> NDArray[np.int64]:
    """The ring of each light (T,): rings of equal inclination, numbered from the top."""
    directions = field.light_directions
    if field.sample_kind == "pixels":
        directions = rig_to_camera(directions, field.cameras[0])
    inclination = np.degrees(np.arccos(np.clip(directions[:, 2], -1.0, 1.0)))
    order = np.argsort(inclination)
    ring = np.zeros(len(order), dtype=np.int64)
    ring[order] = np.concatenate([[0], np.cumsum(np.diff(inclination[order]) > RING_GAP_DEG)])
    return ring


def lowest_lights(field: ReflectanceField) -> NDArray[np.int64]:
    """The lowest sixth of the lights (at least 3), completed to whole rings: (L,) indices.

    What a use below the measured lights extrapolates from is the lowest lights' neighbours:
    holding these out tests it. Inclinations are in the camera frame for pixel fields; a
    light within :data:`RING_GAP_DEG` of the highest one taken belongs to its ring and is
    taken too.
    """
    directions = field.light_directions
    if field.sample_kind == "pixels":
        directions = rig_to_camera(directions, field.cameras[0])
    inclination = np.degrees(np.arccos(np.clip(directions[:, 2], -1.0, 1.0)))
    order = np.argsort(-inclination)
    count = max(3, len(order) // 6)
    edge = inclination[order[count - 1]]
    return np.sort(np.flatnonzero(inclination > edge - RING_GAP_DEG)).astype(np.int64)


def spread_groups(field: ReflectanceField, count: int) -> NDArray[np.int64]:
    """Each light's group (T,) of ``count`` groups, every group spread over the dome.

    :func:`core.directions.spread_partition`: holding one group out leaves gaps of about the
    dome's own spacing while the rest keeps ``1 - 1/count`` of the lights, close to the
    density the capture's use has.
    """
    if count < 2:
        raise InputError(f"spread groups need a count of 2 or more, got {count}")
    return spread_partition(field.light_directions, count)


def split_lights(field: ReflectanceField, how: str) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The fit and test light indices of one capture (see the module's splits).

    Raises
    ------
    InputError
        An unknown split, or one that leaves fewer than 3 lights on either side.
    """
    t = field.shape[1]
    name, _, seed = how.partition(":")
    index = np.arange(t, dtype=np.int64)
    if name == "every-other":
        test = index[1::2]
    elif name == "rings":
        ring = ring_groups(field)
        if ring.max() < 1:
            raise InputError(f"{field.path}: the lights form one ring; use another split")
        test = index[ring % 2 == 1]
    elif name == "random":
        try:
            rng = np.random.default_rng(int(seed or 0))
        except ValueError:
            raise InputError(f"random:SEED needs a whole number, got {how!r}") from None
        test = np.sort(rng.choice(index, size=t // 2, replace=False))
    else:
        raise InputError(f"unknown split {how!r}; use one of {', '.join(SPLITS)} (random:SEED)")
    fit = np.setdiff1d(index, test)
    if min(len(fit), len(test)) < 3:
        raise InputError(
            f"{field.path}: split {how!r} of {t} lights leaves {len(fit)} to fit and "
            f"{len(test)} to test; each side needs 3 or more"
        )
    return fit, test
