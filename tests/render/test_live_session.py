from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.field_store import ReflectanceField
from processing.panorama import Panorama, read_panorama
from render.engines.modes import most_accurate_mode
from render.live_session import LiveControls, LiveSession, error_picture
from sim.field import field_cameras, simulate_field
from sim.ground_truth import field_truth
from tests.call_counting import counting_calls


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory, courtyard_path: Path) -> LiveSession:
    path = tmp_path_factory.mktemp("live") / "matte.zarr"
    simulate_field(
        path, "diffuse-sphere", lights=12, cameras=field_cameras(8, width=32, height=32),
        points=800,
    )  # fmt: skip
    field = ReflectanceField.open(path)
    panorama = read_panorama(courtyard_path)
    return LiveSession(
        field, most_accurate_mode(field), {"courtyard": panorama}, size=(48, 48),
        truth=field_truth(field.provenance),
    )  # fmt: skip


def test_controls_from_the_page_are_checked_value_by_value() -> None:
    controls = LiveControls(panorama="p")
    assert controls.updated({"yaw_deg": 90, "k": 16.0, "truth": True}).k == 16
    for changes, named in (
        ({"yaw": 1.0}, "unknown control 'yaw'"),
        ({"yaw_deg": "east"}, "yaw_deg"),
        ({"yaw_deg": float("nan")}, "yaw_deg"),
        ({"k": 2.5}, "k"),
        ({"k": 0}, "k must be"),
        ({"exposure": -1.0}, "exposure"),
        ({"truth": "yes"}, "truth"),
        ({"mode": "fast"}, "mode 'fast'"),
        ({"sampler": "magic"}, "sampler 'magic'"),
        ({"inclination_deg": 120.0}, "inclination"),
        ({"zoom": 100.0}, "zoom"),
    ):
        with pytest.raises(InputError, match=named):
            controls.updated(changes)


def test_a_change_costs_what_it_changes(session: LiveSession) -> None:
    first = session.render(session.initial)
    assert first.picture.shape == (48, 48, 3) and first.picture.dtype == np.uint8
    turned = session.render(first.controls.updated({"yaw_deg": 90.0}))
    assert turned.seconds["view"] == 0.0 and turned.seconds["lighting"] > 0.0
    assert not np.array_equal(turned.picture, first.picture)
    orbit = session.render(turned.controls.updated({"azimuth_deg": 40.0}))
    assert orbit.seconds["lighting"] == 0.0 and orbit.seconds["view"] > 0.0
    paper = session.render(orbit.controls.updated({"mode": "paper", "k": 8}))
    assert paper.mode == "sampled, paper"
    assert paper.environment.lights is not None and paper.environment.lights.k == 8
    # The paper's mode keeps the engine of the best mode open: switching back only relights.
    back = session.render(paper.controls.updated({"mode": "best"}))
    assert back.seconds["view"] == 0.0


def test_brighter_exposure_shows_brighter_and_the_truth_is_beside_it(
    session: LiveSession,
) -> None:
    base = session.render(session.initial.updated({"truth": True}))
    brighter = session.render(base.controls.updated({"exposure": 4.0}))
    assert brighter.picture.mean() > base.picture.mean() + 10
    comparison = session.compare_truth()
    assert comparison is not None and comparison.picture.shape == (48, 48, 3)
    assert comparison.relative_rmse < 0.1  # a matte sphere, barycentric or lambert
    assert session.warnings() == session.warnings()  # cached, and a tuple of sentences
    settings = session.settings()
    assert settings["controls"]["exposure"] == 4.0 and settings["panorama"].endswith(".exr")


def test_a_modulation_map_steers_only_sampled_lights(session: LiveSession) -> None:
    modulation = np.ones((16, 32), np.float32)
    modulation[:, :16] = 0.0  # no light from half the panorama
    session.add_modulation("half", modulation)
    paper = session.render(session.initial.updated({"mode": "paper", "modulation": "half"}))
    assert paper.notes == ()
    lights = paper.environment.lights
    assert lights is not None
    best = session.render(paper.controls.updated({"mode": "best"}))
    if best.relight_mode.sampled_k is None:
        assert "not applied" in best.notes[0]
    with pytest.raises(InputError, match="zero everywhere"):
        session.add_modulation("none", np.zeros((4, 8)))
    with pytest.raises(InputError, match="no modulation map 'other'"):
        session.render(session.initial.updated({"modulation": "other"}))
    with pytest.raises(InputError, match="no panorama 'studio'"):
        session.render(session.initial.updated({"panorama": "studio"}))


def test_a_panorama_loaded_again_relights(session: LiveSession) -> None:
    frame = session.render(session.initial)
    dimmer = Panorama(session.panoramas["courtyard"].rgb * np.float32(0.25), "dimmer")
    session.add_panorama("courtyard", dimmer)
    again = session.render(frame.controls)
    assert again.seconds["lighting"] > 0.0
    assert again.image.rgb.sum() == pytest.approx(frame.image.rgb.sum() * 0.25, rel=1e-3)


def test_error_picture_is_the_relative_error() -> None:
    truth = np.ones((2, 2, 3), np.float32)
    rgb = truth.copy()
    rgb[0, 0] = 1.5
    coverage = np.ones((2, 2), bool)
    picture, rmse = error_picture(rgb, truth, coverage)
    assert rmse == pytest.approx(np.sqrt(0.25 / 4))
    assert picture[0, 0].sum() > 600 and picture[1, 1].sum() < 10  # 50 %: bright; 0: dark
    _, nothing = error_picture(rgb, truth, np.zeros((2, 2), bool))
    assert np.isnan(nothing)


def test_a_frame_is_a_relighting_request_adjusted_once(
    session: LiveSession, monkeypatch: pytest.MonkeyPatch
) -> None:
    import processing.panorama
    from render.relighting import PanoramaControls, RelightRequest, relight_request

    rotations = counting_calls(monkeypatch, processing.panorama, "rotate_panorama_yaw", 1)
    for mode in ("paper", "best"):
        controls = session.initial.updated({"mode": mode, "yaw_deg": 23.0, "exposure": 1.5})
        frame = session.render(controls)
        # The yaw is applied once per lighting, by the request (the best mode under the same
        # lighting reuses it); the frame's lighting is that.
        assert rotations == ([23.0] if mode == "paper" else [])
        assert frame.environment.controls.yaw_deg == 23.0
        rotations.clear()
        orbit = session.render(controls.updated({"azimuth_deg": 70.0}))
        assert rotations == [] and orbit.environment is frame.environment
        # What rig relight renders for the same request.
        request = RelightRequest(
            panorama=session.panoramas[controls.panorama],
            camera=orbit.camera,
            lighting=PanoramaControls(yaw_deg=23.0, exposure=1.5),
            mode=orbit.relight_mode,
        )
        relit = relight_request(session.field, request, models=session.best.models)
        assert np.array_equal(relit.image.rgb, orbit.image.rgb) and rotations == [23.0]
        rotations.clear()


def test_a_captures_best_mode_is_rig_relights_choice_under_each_panorama(
    tmp_path: Path, courtyard_path: Path
) -> None:
    from core.directions import hemisphere_layout
    from processing.rti import import_rti
    from render.environment_choice import choose_environment_mode
    from render.relighting import PanoramaControls
    from sim.rti_capture import write_rti_capture

    directions = hemisphere_layout(25, "fibonacci")
    shading = 0.6 / np.pi * np.clip(directions[:, 2], 0.0, None)
    images = np.broadcast_to(shading[:, None, None, None], (25, 6, 8, 3))
    field = import_rti(write_rti_capture(tmp_path / "c", "dome", images, directions, scale=1.0),
                       tmp_path / "f.zarr")  # fmt: skip
    sun = np.full((32, 64, 3), 0.05, dtype=np.float32)
    sun[9, 21] = 4000.0
    panoramas = {"courtyard": read_panorama(courtyard_path), "sun": Panorama(sun, "sun")}
    live = LiveSession(field, most_accurate_mode(field), panoramas)
    assert "chosen at its first frame" in live.best_reason("sun")
    for name, panorama in panoramas.items():
        frame = live.render(live.initial.updated({"panorama": name, "yaw_deg": 40.0}))
        expected = choose_environment_mode(
            field, PanoramaControls().as_seen(panorama, field), fast=True
        )
        assert frame.relight_mode == expected.mode
        # The same choice and figures; the seconds it took differ between the two runs.
        timeless = re.compile(r"\(\d+ s to choose")
        assert timeless.sub("(", live.best_reason(name)) == timeless.sub("(", expected.reason)
    # Chosen once a panorama: turning it keeps the choice.
    again = live.render(live.initial.updated({"panorama": "sun", "yaw_deg": 200.0}))
    assert again.relight_mode == frame.relight_mode
