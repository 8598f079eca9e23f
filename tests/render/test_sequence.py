from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.panorama import read_panorama
from processing.sample_models import SampleModels, fit_sample_models
from render.engines.interpolated import RelightSettings
from render.engines.models import ModelRelightSettings
from render.engines.modes import RelightMode, open_relighter
from render.relighting import PanoramaControls, RelightRequest, prepare_relighting
from render.sequence import SequenceKind, relight_prepared_sequence, relight_sequence
from tests.call_counting import counting_calls
from tests.sim_fields import simulated_field

PAPER = RelightSettings.paper_configuration(k=16)
PRECOMPUTED = ModelRelightSettings(lighting="precomputed", grid_height=8)


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("sequence") / "glossy.zarr"
    return simulated_field(path, "glossy-sphere", lights=16, cameras=8, size=32, points=800)


@pytest.fixture(scope="module")
def models(glossy: ReflectanceField) -> SampleModels:
    return fit_sample_models(glossy)


@pytest.mark.parametrize("kind", ["environment", "turntable"])
@pytest.mark.parametrize("mode", [PAPER, PRECOMPUTED], ids=["paper", "precomputed"])
def test_a_prepared_sequence_turns_from_what_was_prepared(
    glossy: ReflectanceField,
    models: SampleModels,
    courtyard_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    kind: SequenceKind,
    mode: RelightMode,
) -> None:
    import processing.panorama
    import render.engines.models

    panorama = read_panorama(courtyard_path)
    camera = PinholeCamera(20.0, 45.0, width=32, height=32)
    request = RelightRequest(
        panorama=panorama,
        camera=camera,
        lighting=PanoramaControls(yaw_deg=30.0, exposure=1.5),
        mode=mode,
    )
    bare = open_relighter(glossy, mode, models)
    expected = relight_sequence(
        bare, panorama, camera, kind=kind, frames=3, yaw_deg=30.0, exposure=1.5
    )
    prepared = prepare_relighting(glossy, request, models=models)
    rotations = counting_calls(monkeypatch, processing.panorama, "rotate_panorama_yaw", 1)
    prefilters = counting_calls(monkeypatch, render.engines.models, "prefilter_panorama")
    views = counting_calls(monkeypatch, type(prepared.engine), "set_view", 1)
    frames = relight_prepared_sequence(prepared, kind=kind, frames=3)
    assert all(np.array_equal(a, b) for a, b in zip(frames, expected, strict=True))
    # Frame 0 is the engine as prepared: no yaw, view or pre-filter redone; each next yaw
    # adjusts the panorama once, and the precomputed lighting turns the pre-filter it has.
    assert prefilters == []
    if kind == "environment":
        assert rotations == [150.0, 270.0] and views == []
    else:
        assert rotations == [] and len(views) == 2


def test_the_precomputed_lighting_shows_the_adjusted_panorama(
    glossy: ReflectanceField,
    models: SampleModels,
    courtyard_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import processing.panorama

    request = RelightRequest(
        panorama=read_panorama(courtyard_path),
        camera=glossy.cameras[0],
        lighting=PanoramaControls(yaw_deg=60.0, exposure=0.5),
        mode=PRECOMPUTED,
    )
    prepared = prepare_relighting(glossy, request, models=models)
    rotations = counting_calls(monkeypatch, processing.panorama, "rotate_panorama_yaw", 1)
    shown = prepared.engine.environment
    # The request's adjustment, not the panorama adjusted again when read.
    assert shown is prepared.environment and shown.panorama is prepared.seen
    assert (shown.controls.yaw_deg, shown.controls.exposure) == (60.0, 0.5)
    assert rotations == []


def test_a_sequence_is_refused_before_any_work(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    engine = open_relighter(glossy, PAPER)
    panorama = read_panorama(courtyard_path)
    with pytest.raises(InputError, match="unknown sequence 'spin'"):
        relight_sequence(engine, panorama, glossy.cameras[0], kind="spin")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="at least 1 frame"):
        relight_sequence(engine, panorama, glossy.cameras[0], frames=0)
    assert engine.environment is None
