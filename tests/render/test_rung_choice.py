from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from core.directions import angle_between, hemisphere_layout
from core.field_store import ReflectanceField
from processing.rti import import_rti
from render.prediction_methods import MixturePredictor
from render.rung_choice import (
    GAP_EXPONENT,
    INTERPOLATION_FOLDS,
    LOWEST,
    UseGaps,
    choose_light_rung,
    light_folds,
    mixture_members,
)
from sim.rti_capture import write_rti_capture
from tests.full_disk import run_limited

LIGHTS = hemisphere_layout(36, "fibonacci")


def _two_materials(folder: Path) -> ReflectanceField:
    """A capture whose left half is matte and right half shiny (a Phong lobe toward the camera)."""
    cosine = np.clip(LIGHTS[:, 2], 0.0, None)
    toward = LIGHTS + np.array([0.0, 0.0, 1.0])
    half = toward / np.linalg.norm(toward, axis=1)[:, None]
    lobe = 0.5 * half[:, 2] ** 60 * cosine
    images = np.zeros((len(LIGHTS), 8, 12, 3))
    images[:, :, :6] = (0.5 / np.pi * cosine)[:, None, None, None]
    images[:, :, 6:] = (0.1 / np.pi * cosine + lobe)[:, None, None, None]
    lp = write_rti_capture(folder / "capture", "dome", images, LIGHTS, scale=1.0)
    return import_rti(lp, folder / "field.zarr")


def _nearest_degrees(a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
    """Each direction of ``a``'s angle (degrees) to its nearest other in ``b`` (default ``a``)."""
    angles = np.degrees(angle_between(a[:, None], (a if b is None else b)[None]))
    angles[angles < 1e-9] = np.inf
    return angles.min(axis=1)


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return _two_materials(tmp_path_factory.mktemp("two"))


def test_the_folds_hold_out_spread_quarters_and_the_lowest_ones_for_extrapolation(
    capture: ReflectanceField,
) -> None:
    folds = light_folds(capture)
    assert len(folds) == INTERPOLATION_FOLDS == 2
    tested = np.concatenate([test for _, _, test in folds])
    assert len(np.unique(tested)) == len(tested) == capture.shape[1] // 2  # 9 + 9 of 36
    spacing = np.median(_nearest_degrees(capture.light_directions, capture.light_directions))
    for _, fit, test in folds:
        assert np.intersect1d(fit, test).size == 0 and len(fit) + len(test) == capture.shape[1]
        # the held-out lights are spread: each leaves a gap of about one spacing
        assert _nearest_degrees(capture.light_directions[test]).mean() > 1.5 * spacing
        assert _nearest_degrees(capture.light_directions[test]).min() > 1.1 * spacing
    below = np.array([[1.0, 0.0, 0.02]]) / np.linalg.norm([1.0, 0.0, 0.02])
    assert [name for name, _, _ in light_folds(capture, below)][-1] == LOWEST


def test_the_use_gap_scales_only_the_excess_over_the_error_at_the_measured_lights(
    capture: ReflectanceField,
) -> None:
    folds = light_folds(capture)
    assert UseGaps.of(capture, folds, None) == UseGaps(1.0, 0.0)
    between = UseGaps.of(capture, folds, capture.light_directions[:5] * 0.999 + 0.001)
    assert 0.0 <= between.ratio < 0.2 and between.outside == 0.0
    inside, held = np.array([1.0, 4.0]), [np.array([9.0, 4.0]), np.array([9.0, 2.0])]
    expected = UseGaps(0.5, 0.0).use_errors(inside, held)
    np.testing.assert_allclose(expected, [1.0 + 8.0 * 0.5**GAP_EXPONENT, 4.0])


def test_two_materials_are_predicted_by_a_rung_or_a_mixture_that_beats_each_alone(
    capture: ReflectanceField,
) -> None:
    queries = hemisphere_layout(10, "grid")
    choice = choose_light_rung(capture, queries, candidates=["barycentric", "rbf", "hsh3"])
    scores = {s.name: s.psnr for s in choice.scores}
    assert set(scores) == {"barycentric", "rbf", "hsh3", "mixture"}
    assert choice.scores[0].psnr == max(scores.values())
    assert choice.members == tuple(s.name for s in choice.scores if s.name != "mixture")[:3]
    assert choice.weights is not None
    np.testing.assert_allclose(choice.weights.sum(axis=0), 1.0, rtol=1e-5)
    predictor = choice.predictor(capture)
    predicted = predictor.predict(0, queries)
    assert predicted.shape == (10, capture.shape[2], 3)
    if choice.name == "mixture":
        assert isinstance(predictor, MixturePredictor)
        assert scores["mixture"] > max(v for k, v in scores.items() if k != "mixture")


def test_a_mixture_holds_both_networks_wherever_they_rank() -> None:
    quick = ["relief", "adaptive", "barycentric", "rbf"]
    assert mixture_members(quick) == [("relief", "adaptive", "barycentric")]
    nets = ("learned+relief+residual", "learned+residual")
    ranked = [nets[0], "relief", "adaptive", "rbf", nets[1]]
    assert mixture_members(ranked) == [(nets[0], "relief", nets[1]), nets]
    assert mixture_members([nets[1], nets[0]]) == [(nets[1], nets[0])]
    assert mixture_members(["relief", nets[1]]) == [("relief", nets[1])]


def test_a_basis_that_cannot_apply_is_said_and_skipped(tmp_path: Path) -> None:
    directions = hemisphere_layout(12, "fibonacci")
    images = np.broadcast_to((0.3 * directions[:, 2])[:, None, None, None], (12, 4, 4, 3))
    lp = write_rti_capture(tmp_path / "c", "dome", images, directions, scale=1.0)
    field = import_rti(lp, tmp_path / "f.zarr")
    choice = choose_light_rung(field, candidates=["barycentric", "hsh3"], mix=False)
    hsh = next(s for s in choice.scores if s.name == "hsh3")
    assert hsh.psnr == -np.inf and "terms" in hsh.note
    assert choice.name == "barycentric"


_CHOOSE = """
import sys
from core.errors import InputError
from core.field_store import ReflectanceField
from render.rung_choice import choose_light_rung
field = ReflectanceField.open(sys.argv[1])
try:
    choice = choose_light_rung(field, candidates=sys.argv[2:], mix=False)
except InputError as error:
    print("stopped:", error)
else:
    print("chose:", choice.name, [(s.name, s.note) for s in choice.scores])
"""


def test_a_fit_that_cannot_be_saved_stops_the_choice(tmp_path: Path) -> None:
    # The model's fit is saved beside the store; on a full disk (a real file size limit, in a
    # child: tests/full_disk.py) that save fails. The choice had taken its error for "does not
    # apply", left the model out and chosen another rung without a word.
    store = _two_materials(tmp_path).path
    candidates = ["barycentric", "lambert+ggx+residual"]
    # With room on the disk the choice runs (and its kernels are compiled and cached: numba
    # writes its cache files too).
    done = run_limited([sys.executable, "-c", _CHOOSE, str(store), *candidates], limit=1 << 30)
    assert done.stdout.startswith("chose: "), done.stdout + done.stderr
    before = set(tmp_path.iterdir())
    saved = [path for path in before if path.name.startswith("field.zarr.models")]
    assert saved, before
    for path in saved:
        path.unlink()
    done = run_limited([sys.executable, "-c", _CHOOSE, str(store), *candidates], limit=4_000)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("stopped: "), done.stdout
    assert "cannot write" in done.stdout
    assert set(tmp_path.iterdir()) == before - set(saved)  # nothing half-written left
