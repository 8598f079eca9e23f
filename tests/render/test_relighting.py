from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import processing.panorama
from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import ReflectanceField
from processing.panorama import adjust_panorama, read_panorama, visible_environment
from processing.rti import import_rti
from render.engines.interpolated import RelightSettings
from render.engines.modes import MOST_ACCURATE_MODELS, most_accurate_mode, open_relighter
from render.environment_choice import choose_environment_mode
from render.relighting import (
    ModeRequest,
    PanoramaControls,
    RelightRequest,
    choose_mode,
    prepare_relighting,
    relight_request,
)
from sim.rti_capture import write_rti_capture
from tests.call_counting import counting_calls
from tests.sim_fields import simulated_field


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("relighting") / "glossy.zarr"
    return simulated_field(path, "glossy-sphere", lights=16, cameras=8, size=32, points=800)


def test_a_given_mode_relights_as_its_engine_does(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    panorama = read_panorama(courtyard_path)
    camera = PinholeCamera(10.0, 40.0, width=32, height=32)
    mode = RelightSettings.paper_configuration(k=16)
    controls = PanoramaControls(yaw_deg=30.0, exposure=2.0)
    relit = relight_request(
        glossy, RelightRequest(panorama=panorama, camera=camera, lighting=controls, mode=mode)
    )
    engine = open_relighter(glossy, mode)
    engine.set_lighting(panorama, yaw_deg=30.0, exposure=2.0)
    engine.set_view(camera)
    assert np.array_equal(relit.image.rgb, engine.render().rgb)
    assert relit.chosen.mode == mode and relit.chosen.reason is None
    # The paper's configuration interpolates the lights: the guards speak of it.
    assert all(warning.code for warning in relit.warnings)


def test_the_panorama_is_judged_as_the_object_sees_it(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    panorama = read_panorama(courtyard_path)
    controls = PanoramaControls(yaw_deg=90.0, exposure=0.5)
    prepared = prepare_relighting(
        glossy,
        RelightRequest(
            panorama=panorama,
            camera=glossy.cameras[0],
            lighting=controls,
            mode=RelightSettings.paper_configuration(k=16),
        ),
    )
    expected = adjust_panorama(panorama, yaw_deg=90.0, exposure=0.5)
    assert np.allclose(prepared.seen.rgb, expected.rgb)


def test_batch_and_relight_choose_the_same_mode_for_a_field_of_points(
    glossy: ReflectanceField, courtyard_path: Path
) -> None:
    seen = read_panorama(courtyard_path)
    under_panorama = choose_mode(glossy, ModeRequest(), seen)
    without = choose_mode(glossy, ModeRequest(), None)
    expected = most_accurate_mode(glossy)
    assert under_panorama.mode == without.mode == replace(expected.mode)
    assert under_panorama.reason == expected.reason and under_panorama.comparison is not None
    if expected.mode == MOST_ACCURATE_MODELS:
        grid = choose_mode(glossy, ModeRequest(grid=32), None).mode
        assert grid == replace(MOST_ACCURATE_MODELS, grid_height=32)


def test_contradicting_requests_are_refused_before_any_work(glossy: ReflectanceField) -> None:
    with pytest.raises(InputError, match=r"-m 99: .* has only 16 measured lights"):
        choose_mode(glossy, ModeRequest(m=99), None)
    with pytest.raises(InputError, match="field of points: use --scheme"):
        choose_mode(glossy, ModeRequest(method="rbf"), None)
    paper = choose_mode(glossy, ModeRequest(paper=True, k=8), None).mode
    assert paper == RelightSettings.paper_configuration(k=8)
    steered = choose_mode(glossy, ModeRequest(scheme="pixels", interpolation="nearest"), None)
    assert steered.mode == RelightSettings("pixels", interpolation="nearest")


def test_a_field_of_pixels_is_relit_by_the_method_chosen_under_the_panorama(
    tmp_path: Path, courtyard_path: Path
) -> None:
    directions = hemisphere_layout(25, "fibonacci")
    shading = 0.6 / np.pi * np.clip(directions[:, 2], 0.0, None)
    images = np.broadcast_to(shading[:, None, None, None], (25, 6, 8, 3))
    lp = write_rti_capture(tmp_path / "capture", "dome", images, directions, scale=1.0)
    field = import_rti(lp, tmp_path / "field.zarr")
    panorama = read_panorama(courtyard_path)
    request = RelightRequest(
        panorama=panorama, camera=field.cameras[0], mode=ModeRequest(fast=True)
    )
    relit = relight_request(field, request)
    # Chosen under the panorama as the plane sees it: nothing from below its horizon.
    seen = visible_environment(panorama, field.below_horizon)
    expected = choose_environment_mode(field, seen, fast=True)
    assert relit.chosen.mode == expected.mode and relit.chosen.reason
    assert [score.name for score in relit.chosen.scores] == [s.name for s in expected.scores]
    assert relit.image.rgb.shape == (6, 8, 3) and relit.image.coverage.all()
    with pytest.raises(InputError, match="--method rbf chooses the relighting; drop -k"):
        choose_mode(field, ModeRequest(method="rbf", k=8), panorama)


def test_a_request_applies_its_controls_once(
    glossy: ReflectanceField, courtyard_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    panorama = read_panorama(courtyard_path)
    rotations = counting_calls(monkeypatch, processing.panorama, "rotate_panorama_yaw", 1)
    prepared = prepare_relighting(
        glossy,
        RelightRequest(
            panorama=panorama,
            camera=glossy.cameras[0],
            lighting=PanoramaControls(yaw_deg=30.0, exposure=2.0),
            mode=RelightSettings.paper_configuration(k=16),
        ),
    )
    assert rotations == [30.0]
    # The engine's lights are made of the panorama the guards judged, recorded under the controls.
    assert prepared.environment.panorama is prepared.seen
    assert prepared.engine.environment is prepared.environment
    assert (prepared.environment.controls.yaw_deg, prepared.environment.controls.exposure) == (
        30.0,
        2.0,
    )


def test_a_cache_redoes_only_what_a_request_changes(
    glossy: ReflectanceField, courtyard_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from render.engines.models import ModelRelightSettings
    from render.relighting import RelightingCache

    panorama = read_panorama(courtyard_path)
    paper = RelightSettings.paper_configuration(k=16)
    first = RelightRequest(
        panorama=panorama,
        camera=PinholeCamera(10.0, 40.0, width=32, height=32),
        lighting=PanoramaControls(yaw_deg=45.0),
        mode=paper,
    )
    cache = RelightingCache(glossy)
    rotations = counting_calls(monkeypatch, processing.panorama, "rotate_panorama_yaw", 1)
    lit = cache.prepare(first)
    assert lit.seconds["lighting"] > 0.0 and lit.seconds["view"] > 0.0 and rotations == [45.0]
    expected = relight_request(glossy, first).image.rgb
    assert np.array_equal(lit.engine.render().rgb, expected)
    rotations.clear()
    # Another view: the lighting stands.
    orbit = replace(first, camera=PinholeCamera(60.0, 40.0, width=32, height=32))
    moved = cache.prepare(orbit)
    assert moved.seconds["lighting"] == 0.0 and moved.seconds["view"] > 0.0 and rotations == []
    # Another mode under the same lighting: the adjusted panorama is reused, not rotated again.
    models = ModelRelightSettings(lighting="grid", grid_height=8)
    modelled = cache.prepare(replace(orbit, mode=models))
    assert modelled.adjusted is moved.adjusted and rotations == []
    assert modelled.environment.panorama is modelled.seen
    # Back to the paper's mode at another K: its engine holds only lighting, so it is opened
    # anew; the model engine is kept, and its view and lighting with it.
    cache.prepare(replace(orbit, mode=replace(paper, k=8)))
    again = cache.prepare(replace(orbit, mode=models))
    assert again.engine is modelled.engine and again.seconds == {"lighting": 0.0, "view": 0.0}
    turned = cache.prepare(replace(orbit, mode=models, lighting=PanoramaControls(yaw_deg=90.0)))
    assert turned.seconds["lighting"] > 0.0 and rotations == [90.0]
