"""More of issue 28's sweep: --dask values, degenerate light sets, rig sample on a full disk,
views at the poles.

Each case runs through the sweep's machinery (:mod:`tests.app.bad_inputs`: in-process, an
alarm for hangs, nothing may be left behind) on a small workspace of its own: a 12-light pixel
field imported from the bundled RTI capture, and ``.lp`` files and stores whose lights no fit
can use (all in one direction, on the horizon, below it).
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.cli import main
from core.camera_model import PinholeCamera
from core.directions import direction_from_angles_deg
from core.field_store import FieldStoreWriter
from core.lp_format import read_lp, write_lp
from core.sample_data import panorama_path, rti_capture_path
from processing.rti import import_rti, rti_camera
from tests.app.bad_inputs import Case, Workspace, run_case
from tests.full_disk import run_limited

#: The installed ``rig`` command beside this interpreter.
RIG = str(Path(sys.executable).with_name("rig"))

#: Lights of the small captures: 12, as a sparse handheld capture.
COUNT = 12


def _degenerate_lights() -> dict[str, np.ndarray]:
    """Camera-frame (= rig-frame, the camera straight above) light sets no fit can use."""
    rng = np.random.default_rng(28)
    azimuths = np.arange(COUNT) * 360.0 / COUNT
    near = direction_from_angles_deg(30.0, 20.0) + 1e-3 * rng.normal(size=(COUNT, 3))
    return {
        "one": np.tile(direction_from_angles_deg(30.0, 20.0), (COUNT, 1)),
        "near": near / np.linalg.norm(near, axis=1, keepdims=True),
        "horizon": direction_from_angles_deg(azimuths, np.full(COUNT, 90.0)),
        "below": direction_from_angles_deg(azimuths, np.full(COUNT, 120.0)),
    }


def _pixel_store(path: Path, lights: np.ndarray) -> None:
    """A 4 x 6 pixel field under ``lights`` (rig frame), base blocked, values of a Lambertian."""
    camera = rti_camera(6, 4)
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=lights, cameras=[camera],
        image_shape=(4, 6),
        light_model={"type": "directional", "irradiance": 1.0, "below_horizon": "blocked"},
    )  # fmt: skip
    for t, light in enumerate(lights):
        writer.write_slab(0, t, np.full((24, 3), max(light[2], 0.0) + 0.05, np.float32))
    writer.write_visibility(0, np.ones(24, dtype=bool))
    writer.finish()


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    root = tmp_path_factory.mktemp("bad-inputs-more")
    files = root / "files"
    files.mkdir()
    capture = read_lp(rti_capture_path())
    (files / "jpg").symlink_to(rti_capture_path().parent / "jpg")
    chosen = np.linspace(0, len(capture) - 1, COUNT).round().astype(int)
    names = [capture.files[i] for i in chosen]
    write_lp(files / "spread.lp", names, capture.directions[chosen])
    for name, lights in _degenerate_lights().items():
        write_lp(files / f"{name}.lp", names, lights)
        _pixel_store(files / f"{name}.zarr", lights)
    with contextlib.redirect_stderr(io.StringIO()):
        import_rti(files / "spread.lp", root / "field.zarr")
    return Workspace(
        root=root, field=root / "field.zarr", dataset=root / "no-dataset",
        panorama=panorama_path("courtyard"), rti=rti_capture_path(),
    )  # fmt: skip


F = "{files}/"
PANO = "{panorama}"
ACCEPTED = ("give 'local'", "SCHEME://HOST:PORT", "tcp, tls, ws, wss")

CASES: tuple[Case, ...] = (
    # --dask: a ValueError traceback from distributed's registry (before: traceback)
    *(
        Case(f"{argv[0]}: --dask {value}", (*argv, "--dask", value), (f"'{value}'", *ACCEPTED))
        for value in (
            "bogus://x",
            "tcp://host",
            "tcp://host:99999",
            "localhost:8786",
            "tcp://a b:1",
        )
        for argv in (
            ("fit", "{field}", "-o", "{tmp}/f.npz"),
            ("process", "{dataset}", "-o", "{tmp}/p.zarr"),
            ("evaluate", "{field}", "--split", "every-other"),
            ("batch", "{field}", "--env", PANO, "-o", "{tmp}/b.zarr"),
        )
    ),
    # a tls:// scheduler without Dask's TLS settings (before: a TypeError traceback)
    Case(
        "fit: --dask tls:// without TLS settings",
        ("fit", "{field}", "-o", "{tmp}/f.npz", "--dask", "tls://127.0.0.1:9", "--quiet"),
        ("Dask scheduler at tls://127.0.0.1:9", "TLS configuration"),
    ),
    # degenerate .lp captures (before: silent, or 'measured directions 0 and 1 coincide'
    # after minutes of choosing, naming no file)
    *(
        Case(
            f"{command[0]}: {name}.lp",
            (*command[:1], F + f"{name}.lp", *command[1:]),
            (f"files/{name}.lp: ", words),
        )
        for name, words in (
            ("one", "all 12 lights are within 1 degree of one direction"),
            ("near", "all 12 lights are within 1 degree of one direction"),
            ("horizon", "every one of the 12 lights is at or below the horizon"),
            ("below", "every one of the 12 lights is at or below the horizon"),
        )
        for command in (
            ("relight", "--env", PANO, "-o", "{tmp}/r.png"),
            ("evaluate", "--split", "every-other"),
            ("export-web", "-o", "{tmp}/web"),
        )
    ),
    # ... and stores of them (before: fitted and relit; batch --paper relit them, and batch
    # and advise failed naming no file or a subset of it when they failed)
    *(
        Case(
            f"{command[0]}: {name}.zarr",
            (*command[:1], F + f"{name}.zarr", *command[1:]),
            (f"files/{name}.zarr: ", words),
        )
        for name, words in (
            ("one", "within 1 degree of one direction"),
            ("horizon", "at or below the horizon (elevation <= 0"),
            ("below", "at or below the horizon (elevation <= 0"),
        )
        for command in (
            ("fit", "-o", "{tmp}/f.npz"),
            ("relight", "--env", PANO, "-o", "{tmp}/r.png"),
            ("batch", "--env", PANO, "--sequence", "environment", "--paper", "-o", "{tmp}/b.zarr"),
            ("advise", "--env", PANO),
        )
    ),
)


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_a_bad_input_is_refused_clearly(case: Case, workspace: Workspace, tmp_path: Path) -> None:
    outcome = run_case(case, workspace, tmp_path / "case")
    assert outcome.kind == "clear", (
        f"{outcome.kind}: {outcome.detail}\nstdout: {outcome.out}\nstderr: {outcome.err}"
    )


def test_the_spread_capture_and_lights_below_an_open_horizon_are_relit(
    workspace: Workspace, tmp_path: Path
) -> None:
    # The refusals are of the lights, not of the small captures: the same images under
    # spread lights relight, and so do lights below a horizon stated open.
    for source, extra in ((workspace.field, ()), (workspace.root / "files/below.lp",
                                                   ("--below-horizon", "open"))):  # fmt: skip
        target = tmp_path / f"{Path(source).stem}.png"
        argv = ["relight", str(source), "--env", str(workspace.panorama), "--method",
                "light-stage", *extra, "-o", str(target)]  # fmt: skip
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert main(argv) == 0
        assert target.stat().st_size > 0


# --- rig sample on a full disk (a real one: RLIMIT_FSIZE in a child) -------------------------


def test_rig_sample_on_a_full_disk_leaves_no_folder(tmp_path: Path) -> None:
    # Before: the new folder stayed, holding lights.json without its pictures.
    out = tmp_path / "new" / "s"
    done = run_limited([RIG, "sample", str(panorama_path("courtyard")), "-k", "8", "-o",
                        str(out)], limit=3000)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert f"rig sample: error: {out}/overlay.png: cannot write: the file is larger" in done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # neither s, nor the parent made for it, nor parts


def test_rig_sample_on_a_full_disk_keeps_the_earlier_outputs(tmp_path: Path) -> None:
    out = tmp_path / "s"
    pano = str(panorama_path("courtyard"))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["sample", pano, "-k", "8", "-o", str(out)]) == 0
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    assert set(before) == {"lights.json", "overlay.png", "lights.png"}
    done = run_limited([RIG, "sample", pano, "-k", "9", "-o", str(out)], limit=3000)
    assert done.returncode == 2, done.stderr
    assert "cannot write" in done.stderr and "Traceback" not in done.stderr
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before
    assert [path.name for path in tmp_path.iterdir()] == ["s"]


# --- views at the poles ---------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(azimuth=st.floats(-720.0, 720.0), pole=st.sampled_from([0.0, 180.0]))
def test_a_view_at_a_pole_is_the_limit_of_its_neighbours(azimuth: float, pole: float) -> None:
    # `--view 0,0` and `--view 0,180` looked like a degenerate camera basis; it is not: the
    # basis at a pole is orthonormal, right-handed and the limit of the views beside it, so
    # a pole's picture is its neighbour's (the holes of 0,180 are the underside no camera saw,
    # which the relighting reports as holes).
    near = 1e-6 if pole == 0.0 else 180.0 - 1e-6
    at, beside = PinholeCamera(azimuth, pole), PinholeCamera(azimuth, near)
    axes = at.axes()
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-12)
    # right, up and toward the camera: a right-handed frame
    assert np.linalg.det(axes * [[1.0], [1.0], [-1.0]]) == pytest.approx(1.0)
    np.testing.assert_allclose(axes, beside.axes(), atol=1e-7)
    points = np.random.default_rng(0).uniform(-1.0, 1.0, (50, 3))
    for got, expected in zip(at.project(points), beside.project(points), strict=True):
        np.testing.assert_allclose(got, expected, atol=1e-3)
