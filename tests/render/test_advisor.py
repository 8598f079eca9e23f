from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import grid_lights
from processing.panorama import Panorama, read_panorama
from render.advisor import Advice, Advisor, Candidate, capture_density
from render.engines.interpolated import RelightSettings
from render.engines.models import ModelRelightSettings
from render.engines.modes import open_relighter
from sim.field import field_cameras, simulate_field
from sim.ground_truth import shade_environment
from sim.scenes import build_scene

CANDIDATES = [
    Candidate("paper, K=16", RelightSettings.paper_configuration(16)),
    Candidate(
        "every pixel, barycentric",
        RelightSettings(
            scheme="pixels", interpolation="barycentric", view_interpolation="barycentric"
        ),
    ),
    Candidate(
        "lambert+ggx, grid 16",
        ModelRelightSettings(model="lambert+ggx", lighting="grid", grid_height=16),
    ),
]
POINTS = 2000


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    path = tmp_path_factory.mktemp("advisor") / "glossy.zarr"
    cameras = field_cameras(8, width=64, height=64)
    simulate_field(path, "glossy-sphere", lights=12, cameras=cameras, points=POINTS)
    return ReflectanceField.open(path)


@pytest.fixture(scope="module")
def courtyard(courtyard_path: Path) -> Panorama:
    return read_panorama(courtyard_path)


@pytest.fixture(scope="module")
def advisor(glossy: ReflectanceField) -> Advisor:
    return Advisor(glossy, CANDIDATES, samples=800)


@pytest.fixture(scope="module")
def advice(advisor: Advisor, courtyard: Panorama) -> Advice:
    return advisor.advise(courtyard, 0.08)


def _true_error(field: ReflectanceField, mode: object, panorama: Panorama) -> float:
    """Relative RMSE of the relit samples against the simulator at two captured cameras."""
    samples = build_scene("glossy-sphere", POINTS)
    lights = grid_lights(panorama.rgb, 64)
    engine = open_relighter(field, mode)  # type: ignore[arg-type]
    engine.set_lighting(panorama)
    error = energy = 0.0
    for s in (1, 5):
        camera = field.cameras[s]
        truth = shade_environment(samples, camera.position, lights, shadows=False)
        engine.set_view(camera)
        image = engine.render()
        seen = image.needed & field.visibility[s]
        error += float(np.sum((image.radiance[seen] - truth[seen]) ** 2))
        energy += float(np.sum(truth[seen] ** 2))
    return float(np.sqrt(error / energy))


def test_predicted_errors_track_the_ground_truth(
    glossy: ReflectanceField, courtyard: Panorama, advice: Advice
) -> None:
    # Held-out folds leave wider gaps than the field's spacing: predictions lean high, but
    # stay within a small factor of the truth for interpolation and models alike.
    for prediction in advice.predictions:
        truth = _true_error(glossy, prediction.candidate.mode, courtyard)
        assert 0.5 * truth < prediction.error < 4.0 * truth, prediction.candidate.name


def test_a_glossy_field_is_advised_its_lobe_model(advice: Advice) -> None:
    by_name = {p.candidate.name: p for p in advice.predictions}
    model, pixels = by_name["lambert+ggx, grid 16"], by_name["every pixel, barycentric"]
    assert model.lights < 0.1 * pixels.lights and model.views < 0.1 * pixels.views
    assert pixels.lighting == 0.0  # every pixel is its own exact lighting
    assert by_name["paper, K=16"].lighting > 0.05  # 16 lights for the courtyard's sun
    assert advice.choice is model
    assert "choice: lambert+ggx, grid 16" in advice.format()


def test_no_choice_below_what_the_field_can_reach(advisor: Advisor, courtyard: Panorama) -> None:
    advice = advisor.advise(courtyard, 1e-4)
    assert advice.choice is None
    assert "no configuration is predicted within 0.01%" in advice.format()
    with pytest.raises(InputError, match="tolerance"):
        advisor.advise(courtyard, 1.5)


def test_capture_density_grows_where_interpolation_misses(advice: Advice) -> None:
    pixels = [p for p in advice.predictions if p.candidate.name == "every pixel, barycentric"]
    density = capture_density(Advice(None, pixels, 0.2, 800, POINTS), cameras=8, lights=12)
    # error ~ 1 / N: the suggested counts scale with the held-out errors over the target
    target = np.sqrt((0.2**2 - pixels[0].lighting ** 2) / 2)
    assert density.lights == int(np.ceil(12 * pixels[0].lights / target)) > 12
    assert density.cameras == int(np.ceil(8 * pixels[0].views / target)) > 8
    assert capture_density(advice, 8, 12).lights == 12  # the model already suffices
    with pytest.raises(InputError, match="relax the tolerance"):
        capture_density(Advice(None, pixels, 0.003, 800, POINTS), cameras=8, lights=12)


def test_too_few_lights_to_hold_out(tmp_path: Path) -> None:
    path = tmp_path / "few.zarr"
    cameras = field_cameras(4, width=16, height=16)
    simulate_field(path, "diffuse-sphere", lights=6, cameras=cameras, points=200)
    with pytest.raises(InputError, match="6 lights"):
        Advisor(ReflectanceField.open(path), CANDIDATES)
