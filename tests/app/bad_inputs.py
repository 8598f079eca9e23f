"""A sweep of bad inputs over every ``rig`` sub-command: each must be a clear refusal.

Each :class:`Case` is one command line a new user could type (a missing, empty, truncated
or wrong file, a value out of range, a damaged dataset or field store), run in-process
through :func:`app.cli.main` with an alarm (a hang is a finding, not a stuck suite), and
classified:

clear
    the expected status (2 for a refusal, 1 for ``rig verify``'s "damaged") and the
    expected words in the message, which name the file or the value;
unclear
    refused, but the message does not say what the case expects (or says it twice);
traceback
    an exception other than the project's errors left ``main``;
hang
    still running after :data:`HANG_SECONDS`;
silent
    accepted (status 0) where it should have been refused.

``tests/app/test_bad_inputs.py`` requires every case to be clear; ``python -m
tests.app.bad_inputs`` runs the sweep and prints the counts per outcome.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import itertools
import json
import os
import re
import shutil
import signal
import sys
import traceback
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from app.cli import main
from core.image_io import write_exr

#: Flags naming what a command writes.
OUTPUT_FLAGS = ("-o", "--output", "--json", "--write-config")

#: Seconds a bad input may take before it counts as a hang (a refusal takes well under one).
HANG_SECONDS = 60


@dataclass(frozen=True)
class Workspace:
    """What the cases read: a small field, a small dataset, panoramas, and bad files.

    Built once (:func:`build_workspace`); a case that damages something works on a copy.
    """

    root: Path
    field: Path
    dataset: Path
    panorama: Path
    rti: Path

    def file(self, name: str) -> Path:
        """A prepared bad file (see :func:`build_workspace`)."""
        return self.root / "files" / name


Prepare = Callable[[Workspace, Path], None]


@dataclass(frozen=True)
class Case:
    """One bad command line and what its refusal must say.

    ``argv`` may use ``{field}``, ``{dataset}``, ``{panorama}``, ``{rti}``, ``{files}`` (the
    prepared bad files) and ``{tmp}`` (a fresh folder of the case's own, where ``prepare``
    may copy and damage things first).
    """

    name: str
    argv: tuple[str, ...]
    expect: tuple[str, ...]
    status: int = 2
    prepare: Prepare | None = None
    stdout: bool = False  # the expected words are on stdout (rig verify's report)


@dataclass
class Outcome:
    """What running a case gave."""

    kind: str
    status: int | None
    out: str
    err: str
    detail: str = ""
    extra: dict[str, str] = field(default_factory=dict)


class _Hang(Exception):
    pass


def _on_alarm(signum: int, frame: FrameType | None) -> None:
    raise _Hang


def run_case(case: Case, workspace: Workspace, tmp: Path) -> Outcome:
    """Run ``case`` in-process and classify what it did."""
    tmp.mkdir(parents=True, exist_ok=True)
    if case.prepare is not None:
        case.prepare(workspace, tmp)
    argv = [
        part.format(
            field=workspace.field,
            dataset=workspace.dataset,
            panorama=workspace.panorama,
            rti=workspace.rti,
            files=workspace.root / "files",
            tmp=tmp,
        )
        for part in case.argv
    ]
    # A refusal leaves nothing behind: no output file, store or dataset folder that was not
    # there before (a half-made dataset would block the retry).
    outputs = [
        Path(value)
        for flag, value in itertools.pairwise(argv)
        # (lexists: False, not an error, for a name too long or a loop of links)
        if flag in OUTPUT_FLAGS and value.startswith(str(tmp)) and not os.path.lexists(value)
    ]
    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(HANG_SECONDS)
    status: int | None = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = main(argv)
    except _Hang:
        return Outcome("hang", None, out.getvalue(), err.getvalue(), f"> {HANG_SECONDS} s")
    except BaseException:
        return Outcome("traceback", None, out.getvalue(), err.getvalue(), traceback.format_exc())
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    text = (out if case.stdout else err).getvalue()
    if status == 0 and case.status != 0:
        return Outcome("silent", status, out.getvalue(), err.getvalue())
    if "Traceback (most recent call last)" in err.getvalue():
        return Outcome("traceback", status, out.getvalue(), err.getvalue(), "printed")
    missing = [words for words in case.expect if words.format(tmp=tmp) not in text]
    said = out.getvalue().splitlines() + err.getvalue().splitlines()
    # A progress bar redraws its last state on closing: that is not a message said twice.
    said = [line for line in said if not re.search(r"\d+%\|", line)]
    repeated = [line for line, n in Counter(said).items() if n > 1 and line.strip()]
    left = [str(path) for path in outputs if os.path.lexists(path) and case.status != 0]
    left += [str(path) for path in tmp.rglob("*.partial*")]
    if status != case.status or missing or repeated or left:
        detail = f"status {status}, missing {missing}, repeated {repeated}, left behind {left}"
        return Outcome("unclear", status, out.getvalue(), err.getvalue(), detail)
    return Outcome("clear", status, out.getvalue(), err.getvalue())


# --- the workspace ------------------------------------------------------------------------


def build_workspace(root: Path) -> Workspace:
    """Make the small field, dataset and bad files the cases read (about 15 s)."""
    from core.sample_data import panorama_path, rti_capture_path

    root.mkdir(parents=True, exist_ok=True)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        made = main(
            [
                "sim",
                "field",
                "--scene",
                "glossy-sphere",
                "--lights",
                "6",
                "--cameras",
                "3",
                "--points",
                "400",
                "--size",
                "32x32",
                "-o",
                str(root / "field.zarr"),
            ]
        )
        made |= main(
            [
                "capture",
                "--sim",
                "--cameras",
                "2",
                "--lights",
                "3",
                "--size",
                "32",
                "--points",
                "1500",
                "--speed",
                "50",
                "--quiet",
                "-o",
                str(root / "dataset"),
            ]
        )
    if made:
        raise RuntimeError("the bad-input workspace could not be built")
    files = root / "files"
    files.mkdir()
    rng = np.random.default_rng(0)
    sky = (rng.random((16, 32, 3)) + 0.1).astype(np.float32)
    for name in ("zero.png", "zero.hdr", "zero.exr", "zero.jpg", "zero.npz", "zero.toml"):
        (files / name).touch()
    (files / "text.exr").write_text("not an image\n")
    (files / "text.png").write_text("not an image\n")
    (files / "folder.exr").mkdir()
    write_exr(files / "sky.exr", sky)
    whole = (files / "sky.exr").read_bytes()
    (files / "truncated.exr").write_bytes(whole[: len(whole) // 2])
    write_exr(files / "tiny.exr", sky[:1, :2])
    write_exr(files / "square.exr", sky[:, :16])
    write_exr(files / "huge.exr", np.where(np.arange(32)[None, :, None] == 3, 1e30, sky))
    nan = sky.copy()
    nan[2, 3, 1] = np.nan
    write_exr(files / "nan.exr", nan)
    write_exr(files / "black.exr", np.zeros_like(sky))
    write_exr(files / "negative.exr", sky - 0.6)
    write_exr(files / "blackmod.exr", np.zeros((8, 16, 3), np.float32))
    (files / "bad.toml").write_text("this is = = not toml\n")
    (files / "huge-plan.toml").write_text(
        "exposures_ms = [10.0]\n[cameras]\nazimuth_deg = { start = 0, stop = 360, step = 0.036 }"
        "\ninclination_deg = { start = 0, stop = 89.99, step = 0.01 }\n"
        '[lights]\nlayout = "grid"\ncount = 10\n'
    )
    (files / "points.npz").write_bytes(b"PK\x03\x04 not really a zip")
    (files / "existing.png").write_bytes(b"keep me")
    (files / "existing.txt").write_text("keep me\n")
    return Workspace(
        root=root,
        field=root / "field.zarr",
        dataset=root / "dataset",
        panorama=panorama_path("courtyard"),
        rti=rti_capture_path(),
    )


# --- damage, applied to a copy in the case's folder ---------------------------------------


def _copy_field(workspace: Workspace, tmp: Path) -> Path:
    target = tmp / "field.zarr"
    shutil.copytree(workspace.field, target)
    return target


def _copy_dataset(workspace: Workspace, tmp: Path) -> Path:
    target = tmp / "dataset"
    shutil.copytree(workspace.dataset, target, ignore=shutil.ignore_patterns(".lock"))
    return target


def _first_radiance_chunk(store: Path) -> Path:
    return next(p for p in sorted((store / "radiance").rglob("*")) if p.is_file())


def delete_chunk(workspace: Workspace, tmp: Path) -> None:
    """A field store with one radiance chunk deleted."""
    _first_radiance_chunk(_copy_field(workspace, tmp)).unlink()


def truncate_chunk(workspace: Workspace, tmp: Path) -> None:
    """A field store with one radiance chunk cut to half its bytes."""
    chunk = _first_radiance_chunk(_copy_field(workspace, tmp))
    chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])


def nan_radiance(workspace: Workspace, tmp: Path) -> None:
    """A field store whose radiance holds NaN (written behind the writer's back)."""
    import zarr

    group = zarr.open_group(str(_copy_field(workspace, tmp)), mode="r+")
    radiance = group["radiance"]
    slab = np.asarray(radiance[0, 0])
    slab[5, 1] = np.nan
    radiance[0, 0] = slab


def copy_field(workspace: Workspace, tmp: Path) -> None:
    """An intact copy of the field store (to overwrite, or to fit beside)."""
    _copy_field(workspace, tmp)


def copy_dataset(workspace: Workspace, tmp: Path) -> None:
    """An intact copy of the dataset."""
    _copy_dataset(workspace, tmp)


def _images(dataset: Path) -> list[Path]:
    return sorted(p for p in (dataset / "images").rglob("*") if p.is_file())


def delete_image(workspace: Workspace, tmp: Path) -> None:
    """A dataset with one image deleted."""
    _images(_copy_dataset(workspace, tmp))[-1].unlink()


def corrupt_image(workspace: Workspace, tmp: Path) -> None:
    """A dataset with one image cut short (its size differs from the record)."""
    image = _images(_copy_dataset(workspace, tmp))[-1]
    image.write_bytes(image.read_bytes()[:100])


def empty_journal(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose journal was emptied."""
    (_copy_dataset(workspace, tmp) / "journal.jsonl").write_text("")


def delete_journal(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose journal was deleted."""
    (_copy_dataset(workspace, tmp) / "journal.jsonl").unlink()


def garbage_manifest(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose manifest is not JSON."""
    (_copy_dataset(workspace, tmp) / "manifest.json").write_text("{ not json")


#: Brackets of the deep JSON cases: far past Python's recursion limit.
DEEP = 200_000


def deep_manifest(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose manifest is a list nested :data:`DEEP` levels deep."""
    (_copy_dataset(workspace, tmp) / "manifest.json").write_text("[" * DEEP + "]" * DEEP)


def deep_journal_line(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose journal's second line holds a list nested :data:`DEEP` levels deep."""
    journal = _copy_dataset(workspace, tmp) / "journal.jsonl"
    lines = journal.read_text().splitlines(keepends=True)
    lines[1] = '{"type": ' + "[" * DEEP + "]" * DEEP + "}\n"
    journal.write_text("".join(lines))


def _dataset_documents(dataset: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    manifest = json.loads((dataset / "manifest.json").read_text())
    lines = (dataset / "journal.jsonl").read_text().splitlines()
    return manifest, [json.loads(line) for line in lines]


def _write_documents(dataset: Path, manifest: dict[str, Any], journal: list[Any]) -> None:
    (dataset / "manifest.json").write_text(json.dumps(manifest))
    (dataset / "journal.jsonl").write_text("".join(json.dumps(d) + "\n" for d in journal))


def _records(manifest: dict[str, Any], journal: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every image record: the manifest's and the journal events'."""
    events = [document["record"] for document in journal if document["type"] == "event"]
    return [*manifest["images"], *events]


def _revouch(dataset: Path) -> None:
    """Write every file's SHA-256 and size into its records, as a 'repair' script would."""
    manifest, journal = _dataset_documents(dataset)
    for record in _records(manifest, journal):
        data = (dataset / record["file"]).read_bytes()
        record.update(sha256=hashlib.sha256(data).hexdigest(), size_bytes=len(data))
    _write_documents(dataset, manifest, journal)


def _two_light_images(dataset: Path) -> tuple[str, str]:
    names = sorted(p.name for p in (dataset / "images").iterdir() if p.name.startswith("light"))
    return f"images/{names[-2]}", f"images/{names[-1]}"


def swapped_images(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose two light images were swapped, every checksum then re-vouched."""
    dataset = _copy_dataset(workspace, tmp)
    a, b = (dataset / name for name in _two_light_images(dataset))
    data = a.read_bytes()
    a.write_bytes(b.read_bytes())
    b.write_bytes(data)
    _revouch(dataset)


def records_naming_each_others_files(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose two records name each other's files (checksums following the files)."""
    dataset = _copy_dataset(workspace, tmp)
    a, b = _two_light_images(dataset)
    manifest, journal = _dataset_documents(dataset)
    for record in _records(manifest, journal):
        record["file"] = {a: b, b: a}.get(record["file"], record["file"])
    _write_documents(dataset, manifest, journal)
    _revouch(dataset)


#: The dataset id of "another dataset" (a UUID's form).
OTHER_DATASET = "0e7e7000-0000-4000-8000-000000000000"


def _as_another_capture(documents: list[dict[str, Any]]) -> None:
    """Records and runs as another capture of the same plan would have written them.

    Other checksums (no two captures give the same bytes: sensor noise), other run uids, and
    the other dataset's id where the documents carry one.
    """
    uids: dict[str, str] = {}
    for document in documents:
        record = document.get("record", document)
        if "sha256" in record:
            record["sha256"] = hashlib.sha256(record["sha256"].encode()).hexdigest()
        for name in ("uid", "run_start", "resumed_from"):
            if isinstance(document.get(name), str):
                document[name] = uids.setdefault(document[name], str(uuid.uuid4()))
        if "dataset_id" in document:
            document["dataset_id"] = OTHER_DATASET


def another_datasets_journal(workspace: Workspace, tmp: Path) -> None:
    """A dataset holding the journal of another capture of the same plan."""
    dataset = _copy_dataset(workspace, tmp)
    manifest, journal = _dataset_documents(dataset)
    _as_another_capture(journal)
    _write_documents(dataset, manifest, journal)


def another_datasets_manifest(workspace: Workspace, tmp: Path) -> None:
    """A dataset holding the manifest of another capture of the same plan."""
    dataset = _copy_dataset(workspace, tmp)
    manifest, journal = _dataset_documents(dataset)
    _as_another_capture([manifest, *manifest["images"]])
    _write_documents(dataset, manifest, journal)


def moved_light(workspace: Workspace, tmp: Path) -> None:
    """A dataset whose plan was edited in its manifest after the capture: a light moved."""
    dataset = _copy_dataset(workspace, tmp)
    manifest, journal = _dataset_documents(dataset)
    manifest["plan"]["lights"][1][0] += 20.0
    _write_documents(dataset, manifest, journal)


def altered_attribute(name: str, value: object) -> Prepare:
    """A copy of the field whose attribute ``name`` is ``value`` (written behind its back)."""

    def prepare(workspace: Workspace, tmp: Path) -> None:
        import zarr

        zarr.open_group(str(_copy_field(workspace, tmp)), mode="r+").attrs[name] = value

    return prepare


def scaled_light_directions(scale: float) -> Prepare:
    """A copy of the field whose light directions are scaled (NaN: light 2 made NaN)."""

    def prepare(workspace: Workspace, tmp: Path) -> None:
        import zarr

        group = zarr.open_group(str(_copy_field(workspace, tmp)), mode="r+")
        directions = np.asarray(group["light_directions"][...])
        if np.isnan(scale):
            directions[2] = np.nan
        else:
            directions *= scale
        group["light_directions"][...] = directions

    return prepare


#: Store attributes of the wrong type (issue 28): each was a traceback from core.field_store.
ALTERED_ATTRIBUTES: tuple[tuple[str, str, object, str], ...] = (
    ("samples a string", "samples", "points", "attribute samples is 'points'"),
    ("pixels without height", "samples", {"kind": "pixels", "width": 20}, "attribute samples"),
    ("dark_cameras ['x']", "dark_cameras", ["x"], "attribute dark_cameras is ['x']"),
    ("light_model a string", "light_model", "directional", "attribute light_model is"),
    ("provenance a list", "provenance", [1, 2], "attribute provenance is [1, 2]"),
    ("radiance_digest a number", "radiance_digest", 5, "attribute radiance_digest is 5"),
    ("cameras a string", "cameras", "abc", "attribute cameras is 'abc'"),
)


def a_link_loop(workspace: Workspace, tmp: Path) -> None:
    """``loop``: a symbolic link to itself, where an output or its folder is named."""
    (tmp / "loop").symlink_to("loop")


def fifos(workspace: Workspace, tmp: Path) -> None:
    """FIFOs (named pipes) where files are wanted: ``fifo.toml``, ``fifo.exr``, ``fifo.lp``.

    Nothing ever writes into them: a reader that opens one waits forever.
    """
    for name in ("fifo.toml", "fifo.exr", "fifo.lp"):
        os.mkfifo(tmp / name)


def claiming_plys(workspace: Workspace, tmp: Path) -> None:
    """PLY files whose header claims far more vertices than they hold (one each).

    ``ascii.ply`` claims 99,999,999,999 (a reader looped over the claim), ``binary.ply``
    10^12 (a reader asked for terabytes).
    """
    properties = "".join(f"property float {n}\n" for n in ("x", "y", "z", "nx", "ny", "nz"))
    for name, encoding, count, body in (
        ("ascii.ply", "ascii", 99_999_999_999, b"0 0 0 0 0 1\n"),
        ("binary.ply", "binary_little_endian", 10**12, bytes(24)),
    ):
        header = f"ply\nformat {encoding} 1.0\nelement vertex {count}\n{properties}end_header\n"
        (tmp / name).write_bytes(header.encode() + body)


def deep_toml(workspace: Workspace, tmp: Path) -> None:
    """``deep.toml``: an array nested :data:`DEEP` levels deep (a config, plan or world)."""
    (tmp / "deep.toml").write_text("a = " + "[" * DEEP + "]" * DEEP + "\n")


def garbage_models(workspace: Workspace, tmp: Path) -> None:
    """A copy of the field with a model fit beside it that is not an npz file."""
    store = _copy_field(workspace, tmp)
    (store.parent / (store.name + ".models.npz")).write_bytes(b"not a zip")


def other_field_models(workspace: Workspace, tmp: Path) -> None:
    """A copy of the field with a fit of a different field saved beside it."""
    store = _copy_field(workspace, tmp)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        main(
            [
                "sim",
                "field",
                "--scene",
                "diffuse-sphere",
                "--lights",
                "6",
                "--cameras",
                "3",
                "--points",
                "400",
                "--size",
                "32x32",
                "-o",
                str(tmp / "other.zarr"),
            ]
        )
    from core.field_store import ReflectanceField
    from processing.sample_model_store import models_for_field

    with contextlib.redirect_stderr(io.StringIO()):
        models_for_field(ReflectanceField.open(tmp / "other.zarr"), tmp / "other.npz")
    del store


def four_light_field(workspace: Workspace, tmp: Path) -> None:
    """``four.zarr``: a field of 4 lights (too few to split)."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        main(
            [
                "sim",
                "field",
                "--scene",
                "glossy-sphere",
                "--lights",
                "4",
                "--cameras",
                "3",
                "--points",
                "400",
                "--size",
                "32x32",
                "-o",
                str(tmp / "four.zarr"),
            ]
        )


def hostile_numbers(workspace: Workspace, tmp: Path) -> None:
    """The example config and plan with one number at the edge of a float each."""
    config = Path("docs/rig.example.toml").read_text(encoding="utf-8")
    plan = Path("docs/plan.example.toml").read_text(encoding="utf-8")
    for name, text, old, new in (
        ("step.toml", config, "path_step_deg = 1.0", "path_step_deg = 1e-12"),
        ("limit.toml", config, "min_deg = -170.0", "min_deg = -1e308"),
        ("feed.toml", config, "feed_deg_min = 3600.0", "feed_deg_min = 1e-300"),
        ("exposure.toml", plan, "exposures_ms = [10.0, 40.0, 160.0]", "exposures_ms = [1e308]"),
        ("many.toml", plan, "exposures_ms = [10.0, 40.0, 160.0]",
         "exposures_ms = [" + ", ".join(["10.0"] * 50_000) + "]"),
        ("range.toml", plan, "start = -157.5, stop = 157.5, step = 45",
         "start = -1e308, stop = 1e308, step = 45"),
        ("tiny.toml", plan, "start = -157.5, stop = 157.5, step = 45",
         "start = -157.5, stop = 157.5, step = 5e-324"),
    ):  # fmt: skip
        assert old in text, (name, old)
        (tmp / name).write_text(text.replace(old, new), encoding="utf-8")


def two_lights_lp(workspace: Workspace, tmp: Path) -> None:
    """``two.lp`` (two lights from above) and ``escape.lp`` (an entry naming ../x.png)."""
    (tmp / "two.lp").write_text("2\na.png 0 0 1\nb.png 0.5 0 0.87\n")
    (tmp / "escape.lp").write_text("1\n../x.png 0 0 1\n")
    (tmp / "same.lp").write_text("2\na.png 0 0 1\na.jpg 0.5 0 0.87\n")
    (tmp / "dot.lp").write_text("1\n. 0 0 1\n")
    (tmp / "nul.lp").write_text("1\na\x00b.png 0 0 1\n")


def an_output_folder(workspace: Workspace, tmp: Path) -> None:
    """A non-empty folder where an output file or store is asked for."""
    (tmp / "out.png").mkdir()
    (tmp / "out.png" / "x").write_text("x")
    (tmp / "taken").mkdir()
    (tmp / "taken" / "keep.txt").write_text("keep me")


# --- the cases ---------------------------------------------------------------------------

F = "{files}/"


def _panorama_cases(command: tuple[str, ...], flag: tuple[str, ...] = ()) -> list[Case]:
    """Bad panorama files given to a command that reads one (``flag`` before the path)."""
    name = " ".join(command[:2])
    # One row a bad file: a table of (what, file, words), alike in shape to any other table.
    return [
        Case(f"{name}: {what}", (*command, *flag, F + file), (file, words))
        for what, file, words in (
            ("missing panorama", "nowhere.exr", "no such file"),
            ("zero-byte .png", "zero.png", "empty"),
            ("zero-byte .hdr", "zero.hdr", "empty"),
            ("zero-byte .exr", "zero.exr", "empty"),
            ("text as .exr", "text.exr", "exr"),
            ("truncated .exr", "truncated.exr", "truncated.exr"),
            ("directory as a file", "folder.exr", "is a directory"),
            ("1x2 image", "tiny.exr", "too small"),
            ("non-2:1 image", "square.exr", "twice as wide"),
            ("values of 1e30", "huge.exr", "1e+30"),
            ("a NaN", "nan.exr", "NaN"),
            ("all black", "black.exr", "no light"),
            ("material negatives", "negative.exr", "negative radiance"),
            ("unknown format", "zero.toml", "unknown image format"),
        )
    ]


def _cases() -> list[Case]:
    # A table, repeated on purpose: each case spells out the command line a user types and
    # what its refusal must say, so the cases of one command share a shape (duplicates pairs
    # them); a builder per command would hide the very line under test.
    pano = "{panorama}"
    relight = ("relight", "{field}", "--env", pano, "--view", "20,40", "--size", "32x32")
    relight_png = (*relight, "-o", "{tmp}/r.png")
    field = (
        "sim",
        "field",
        "--scene",
        "glossy-sphere",
        "--lights",
        "4",
        "--cameras",
        "2",
        "--points",
        "300",
        "--size",
        "32x32",
    )
    render = (
        "sim",
        "render",
        "--scene",
        "glossy-sphere",
        "--env",
        pano,
        "--view",
        "0,30",
        "--size",
        "32x32",
        "--points",
        "500",
        "-o",
        "{tmp}/gt.exr",
    )
    photo = (
        "sim",
        "photo",
        "--scene",
        "glossy-sphere",
        "--view",
        "0,30",
        "--light",
        "0,60",
        "--size",
        "32x32",
        "--points",
        "500",
    )
    cases: list[Case] = []
    # rig sample
    sample = ("sample", "-o", "{tmp}/s")
    cases += _panorama_cases(sample)
    cases += [
        Case("sample: -k 0", (*sample, pano, "-k", "0"), ("-k", "at least 1")),
        Case("sample: -k abc", (*sample, pano, "-k", "abc"), ("-k", "'abc'")),
        Case(
            "sample: -k above the pixels",
            (*sample, F + "sky.exr", "-k", "100000"),
            ("100000", "pixels"),
        ),
        Case("sample: --seed -1", (*sample, pano, "--seed", "-1"), ("--seed",)),
        Case("sample: --yaw nan", (*sample, pano, "--yaw", "nan"), ("--yaw", "finite")),
        Case("sample: --exposure 0", (*sample, pano, "--exposure", "0"), ("--exposure",)),
        Case("sample: --exposure 1e20", (*sample, pano, "--exposure", "1e20"), ("exposure 1e+20",)),
        Case(
            "sample: zero-byte --modulation",
            (*sample, pano, "--modulation", F + "zero.png"),
            ("zero.png", "empty"),
        ),
        Case(
            "sample: missing --modulation",
            (*sample, pano, "--modulation", F + "no.png"),
            ("no.png", "no such file"),
        ),
        Case(
            "sample: black --modulation",
            (*sample, pano, "--modulation", F + "blackmod.exr"),
            ("blackmod.exr", "zero"),
        ),
        Case(
            "sample: -o an existing file",
            ("sample", pano, "-o", F + "existing.txt"),
            ("existing.txt", "not a directory"),
        ),
        Case(
            "sample: -o under a file",
            ("sample", pano, "-o", F + "existing.txt/x"),
            ("existing.txt", "not a directory"),
        ),
    ]
    # rig relight
    cases += _panorama_cases(
        ("relight", "{field}", "-o", "{tmp}/r.png", "--view", "20,40"), ("--env",)
    )
    cases += [
        Case(
            "relight: missing field",
            ("relight", "{tmp}/none.zarr", "--env", pano, "-o", "{tmp}/r.png"),
            ("none.zarr", "no such"),
        ),
        Case(
            "relight: a dataset as the field",
            ("relight", "{dataset}", "--env", pano, "-o", "{tmp}/r.png"),
            ("dataset", "neither a field store"),
        ),
        Case(
            "relight: a file as the field",
            ("relight", F + "existing.txt", "--env", pano, "-o", "{tmp}/r.png"),
            ("existing.txt",),
        ),
        Case(
            "relight: no --view for points",
            ("relight", "{field}", "--env", pano, "-o", "{tmp}/r.png"),
            ("--view",),
        ),
        Case("relight: --view a,b", (*relight_png, "--view", "a,b"), ("--view", "AZ,INCL")),
        Case("relight: --view 1,2,3", (*relight_png, "--view", "1,2,3"), ("--view", "1,2,3")),
        Case(
            "relight: --distance 0.5",
            (*relight_png, "--distance", "0.5"),
            ("distance 0.5", "inside the object"),
        ),
        Case("relight: --distance 0", (*relight_png, "--distance", "0"), ("--distance",)),
        Case(
            "relight: --size 100000x100000",
            (*relight_png, "--size", "100000x100000"),
            ("--size", "100000x100000"),
        ),
        Case("relight: --size 0x5", (*relight_png, "--size", "0x5"), ("--size", "0x5")),
        Case("relight: --size 9e9x2", (*relight_png, "--size", "big"), ("--size", "'big'")),
        Case("relight: --fov 0", (*relight_png, "--fov", "0"), ("--fov",)),
        Case("relight: --fov 180", (*relight_png, "--fov", "180"), ("field of view", "180")),
        Case("relight: --fps 0 to GIF", (*relight, "-o", "{tmp}/r.gif", "--fps", "0"), ("--fps",)),
        Case(
            "relight: --fps -5 to GIF", (*relight, "-o", "{tmp}/r.gif", "--fps", "-5"), ("--fps",)
        ),
        Case("relight: --fps 0 to MP4", (*relight, "-o", "{tmp}/r.mp4", "--fps", "0"), ("--fps",)),
        Case(
            "relight: --frames 0", (*relight, "-o", "{tmp}/r.gif", "--frames", "0"), ("--frames",)
        ),
        Case("relight: -m 99 with 6 lights", (*relight_png, "-m", "99"), ("-m 99", "6")),
        Case("relight: -n 99 with 3 cameras", (*relight_png, "-n", "99"), ("-n 99", "3")),
        Case("relight: -k 0", (*relight_png, "-k", "0"), ("-k",)),
        Case("relight: --grid 0", (*relight_png, "--scheme", "model", "--grid", "0"), ("--grid",)),
        Case("relight: --yaw inf", (*relight_png, "--yaw", "inf"), ("--yaw",)),
        Case("relight: --exposure -1", (*relight_png, "--exposure", "-1"), ("--exposure",)),
        Case(
            "relight: --models a folder",
            (*relight_png, "--scheme", "model", "--models", "{tmp}/taken"),
            ("taken", "not a readable models file"),
            prepare=an_output_folder,
        ),
        Case(
            "relight: --models not a fit",
            (*relight_png, "--scheme", "model", "--models", F + "points.npz"),
            ("points.npz",),
        ),
        Case(
            "relight: a damaged saved fit",
            (
                "relight",
                "{tmp}/field.zarr",
                "--env",
                pano,
                "--view",
                "20,40",
                "--size",
                "32x32",
                "--scheme",
                "model",
                "-o",
                "{tmp}/r.png",
            ),
            ("field.zarr.models.npz",),
            prepare=garbage_models,
        ),
        Case(
            "relight: another field's fit",
            (*relight_png, "--scheme", "model", "--models", "{tmp}/other.npz"),
            ("other.npz", "fitted to other data"),
            prepare=other_field_models,
        ),
        Case(
            "relight: -o a directory",
            (*relight, "-o", "{tmp}/out.png"),
            ("out.png", "directory"),
            prepare=an_output_folder,
        ),
        Case(
            "relight: -o under a file",
            (*relight, "-o", F + "existing.txt/r.png"),
            ("existing.txt", "not a directory"),
        ),
        Case("relight: -o .bmp", (*relight, "-o", "{tmp}/r.bmp"), ("r.bmp",)),
        Case(
            "relight: modulation with every pixel",
            (*relight_png, "--scheme", "pixels", "--modulation", F + "sky.exr"),
            ("modulation map", "every part of the panorama"),
        ),
        Case(
            "relight: zero-byte --modulation",
            (*relight_png, "-k", "8", "--modulation", F + "zero.png"),
            ("zero.png", "empty"),
        ),
        Case(
            "relight: turntable of a pixel field",
            ("relight", "{rti}", "--env", pano, "-o", "{tmp}/r.gif", "--sequence", "turntable"),
            ("one fixed view", "--sequence environment"),
        ),
        Case(
            "relight: a field with a missing chunk",
            (
                "relight",
                "{tmp}/field.zarr",
                "--env",
                pano,
                "--view",
                "20,40",
                "--size",
                "32x32",
                "-k",
                "8",
                "-o",
                "{tmp}/r.png",
            ),
            ("field.zarr", "missing", "camera 0 light 0"),
            prepare=delete_chunk,
        ),
        Case(
            "relight: a field with a truncated chunk",
            (
                "relight",
                "{tmp}/field.zarr",
                "--env",
                pano,
                "--view",
                "20,40",
                "--size",
                "32x32",
                "-k",
                "8",
                "-o",
                "{tmp}/r.png",
            ),
            ("field.zarr", "camera 0 light 0"),
            prepare=truncate_chunk,
        ),
        Case(
            "relight: a field holding NaN",
            (
                "relight",
                "{tmp}/field.zarr",
                "--env",
                pano,
                "--view",
                "20,40",
                "--size",
                "32x32",
                "-k",
                "8",
                "-o",
                "{tmp}/r.png",
            ),
            ("field.zarr", "non-finite", "camera 0"),
            prepare=nan_radiance,
        ),
    ]
    # field stores altered behind the writer's back
    altered = (
        "relight", "{tmp}/field.zarr", "--env", pano, "--view", "20,40", "--size", "32x32",
        "-o", "{tmp}/r.png",
    )  # fmt: skip
    for what, name, value, words in ALTERED_ATTRIBUTES:
        prepare = altered_attribute(name, value)
        cases += [
            Case(f"relight: {what}", altered, ("field.zarr", words), prepare=prepare),
            Case(
                f"verify: {what}",
                ("verify", "{tmp}/field.zarr", "--quiet"),
                (words,),
                status=1,
                prepare=prepare,
                stdout=True,
            ),
        ]
    for what, scale, words in (
        ("light directions of length 10", 10.0, "light direction 0 is"),
        ("NaN light directions", float("nan"), "light direction 2 is (nan, nan, nan)"),
    ):
        prepare = scaled_light_directions(scale)
        cases += [
            Case(f"relight: {what}", altered, ("field.zarr", words), prepare=prepare),
            Case(
                f"fit: {what}",
                ("fit", "{tmp}/field.zarr", "--quiet"),
                ("field.zarr", words),
                prepare=prepare,
            ),
            Case(
                f"evaluate: {what}",
                ("evaluate", "{tmp}/field.zarr", "--split", "rings", "--quiet"),
                ("field.zarr", words),
                prepare=prepare,
            ),
        ]
    cases.append(
        Case(
            "verify: light directions of length 10",
            ("verify", "{tmp}/field.zarr", "--quiet"),
            ("light direction 0 is", "of length 10"),
            status=1,
            prepare=scaled_light_directions(10.0),
            stdout=True,
        )
    )
    # TOML nested 200,000 deep (tomllib recursed until RecursionError)
    cases += [
        Case(
            "plan: a config nested 200,000 deep",
            ("plan", "--config", "{tmp}/deep.toml", "--plan", "docs/plan.example.toml"),
            ("deep.toml", "rig config is nested too deeply"),
            prepare=deep_toml,
        ),
        Case(
            "plan: a plan nested 200,000 deep",
            ("plan", "--config", "docs/rig.example.toml", "--plan", "{tmp}/deep.toml"),
            ("deep.toml", "plan is nested too deeply"),
            prepare=deep_toml,
        ),
        Case(
            "sim rti: a world nested 200,000 deep",
            ("sim", "rti", "--scene", "{tmp}/deep.toml", "-o", "{tmp}/d"),
            ("deep.toml", "world file is nested too deeply"),
            prepare=deep_toml,
        ),
    ]
    # outputs no file system can name
    long_name = "{tmp}/" + "a" * 256 + ".png"
    cases += [
        Case(
            "relight: -o a 256-byte name",
            (*relight, "-o", long_name),
            ("a" * 24, "260 bytes long", "choose a shorter name"),
        ),
        Case(
            "relight: -o through a symlink loop",
            (*relight, "-o", "{tmp}/loop/r.png"),
            ("loop/r.png", "loop of symbolic links"),
            prepare=a_link_loop,
        ),
        Case(
            "relight: -o a symlink loop",
            (*relight, "-o", "{tmp}/loop"),
            ("loop", "loop of symbolic links"),
            prepare=a_link_loop,
        ),
        Case(
            "sample: -o a symlink loop",
            ("sample", pano, "-o", "{tmp}/loop"),
            ("loop", "loop of symbolic links"),
            prepare=a_link_loop,
        ),
        Case(
            "sim photo: -o a 256-byte name",
            (*photo, "-o", long_name),
            ("260 bytes long", "choose a shorter name"),
        ),
    ]
    # files that never answer: FIFOs and devices where a file is wanted, PLY counts
    fifo = "is a FIFO (named pipe), not a regular file"
    cases += [
        Case(
            "plan: --config a FIFO",
            ("plan", "--config", "{tmp}/fifo.toml", "--plan", "docs/plan.example.toml"),
            ("fifo.toml", fifo),
            prepare=fifos,
        ),
        Case(
            "doctor: --config a FIFO",
            ("doctor", "--config", "{tmp}/fifo.toml"),
            ("fifo.toml", fifo),
            prepare=fifos,
        ),
        Case(
            "capture: --config a FIFO",
            (
                "capture",
                "--config",
                "{tmp}/fifo.toml",
                "--plan",
                "docs/plan.example.toml",
                "-o",
                "{tmp}/d",
            ),
            ("fifo.toml", fifo),
            prepare=fifos,
        ),
        Case(
            "relight: --env a FIFO",
            (
                "relight",
                "{field}",
                "--env",
                "{tmp}/fifo.exr",
                "--view",
                "20,40",
                "-o",
                "{tmp}/r.png",
            ),
            ("fifo.exr", fifo),
            prepare=fifos,
        ),
        Case(
            "relight: --env /dev/zero",
            ("relight", "{field}", "--env", "/dev/zero", "--view", "20,40", "-o", "{tmp}/r.png"),
            ("/dev/zero: is a character device",),
        ),
        Case(
            "relight: -o /dev/null",
            (*relight, "-o", "/dev/null"),
            ("/dev/null: is a character device",),
        ),
        Case(
            "sample: a FIFO panorama",
            ("sample", "{tmp}/fifo.exr", "-o", "{tmp}/s"),
            ("fifo.exr", fifo),
            prepare=fifos,
        ),
        Case(
            "evaluate: --test a FIFO",
            ("evaluate", "{field}", "--test", "{tmp}/fifo.lp", "--quiet"),
            ("fifo.lp", fifo),
            prepare=fifos,
        ),
        Case(
            "sim rti: --scene a FIFO",
            ("sim", "rti", "--scene", "{tmp}/fifo.toml", "-o", "{tmp}/d"),
            ("fifo.toml", fifo),
            prepare=fifos,
        ),
        Case(
            "process: a PLY claiming 99,999,999,999 vertices",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--points", "{tmp}/ascii.ply"),
            ("ascii.ply", "claims 99999999999 vertices", "hold at most 1"),
            prepare=claiming_plys,
        ),
        Case(
            "process: a binary PLY claiming 10^12 vertices",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--points", "{tmp}/binary.ply"),
            ("binary.ply", "claims 1000000000000 vertices", "hold at most 1"),
            prepare=claiming_plys,
        ),
    ]
    # rig verify
    cases += [
        Case("verify: missing path", ("verify", "{tmp}/none"), ("none", "no such")),
        Case("verify: a file", ("verify", F + "existing.txt"), ("existing.txt",)),
        Case("verify: an empty folder", ("verify", "{tmp}"), ("manifest",)),
        Case(
            "verify: a deleted image",
            ("verify", "{tmp}/dataset"),
            ("missing",),
            status=1,
            prepare=delete_image,
            stdout=True,
        ),
        Case(
            "verify: a cut image",
            ("verify", "{tmp}/dataset"),
            ("corrupt",),
            status=1,
            prepare=corrupt_image,
            stdout=True,
        ),
        Case(
            "verify: an emptied journal",
            ("verify", "{tmp}/dataset"),
            ("not journaled", "journal.jsonl"),
            status=1,
            prepare=empty_journal,
            stdout=True,
        ),
        Case(
            "verify: a deleted journal",
            ("verify", "{tmp}/dataset"),
            ("not journaled", "journal.jsonl"),
            status=1,
            prepare=delete_journal,
            stdout=True,
        ),
        Case(
            "verify: two images swapped, checksums re-vouched",
            ("verify", "{tmp}/dataset"),
            ("NOT OK", "holds the image of", "swapped or renamed"),
            status=1,
            prepare=swapped_images,
            stdout=True,
        ),
        Case(
            "verify: records naming each other's files",
            ("verify", "{tmp}/dataset"),
            ("NOT OK", "holds the image of", "swapped or renamed"),
            status=1,
            prepare=records_naming_each_others_files,
            stdout=True,
        ),
        Case(
            "verify: another dataset's journal",
            ("verify", "{tmp}/dataset"),
            ("journal.jsonl belongs to another dataset", OTHER_DATASET, "put back"),
            status=1,
            prepare=another_datasets_journal,
            stdout=True,
        ),
        Case(
            "verify: another dataset's manifest",
            ("verify", "{tmp}/dataset"),
            ("manifest.json belongs to another dataset", OTHER_DATASET, "put back"),
            status=1,
            prepare=another_datasets_manifest,
            stdout=True,
        ),
        Case(
            "verify: a light moved in the plan",
            ("verify", "{tmp}/dataset"),
            ("differs from the plan the dataset was captured with", "lights[1] was"),
            status=1,
            prepare=moved_light,
            stdout=True,
        ),
        Case(
            "verify: a manifest not JSON",
            ("verify", "{tmp}/dataset"),
            ("manifest.json",),
            prepare=garbage_manifest,
        ),
        Case(
            "verify: a manifest nested 200,000 deep",
            ("verify", "{tmp}/dataset"),
            ("manifest.json", "JSON nested too deeply"),
            prepare=deep_manifest,
        ),
        Case(
            "verify: a journal line nested 200,000 deep",
            ("verify", "{tmp}/dataset"),
            ("journal.jsonl, line 2", "JSON nested too deeply"),
            prepare=deep_journal_line,
        ),
        Case(
            "verify: a store missing a chunk",
            ("verify", "{tmp}/field.zarr", "--quiet"),
            ("missing", "camera 0 light 0"),
            status=1,
            prepare=delete_chunk,
            stdout=True,
        ),
        Case(
            "verify: a store with a cut chunk",
            ("verify", "{tmp}/field.zarr", "--quiet"),
            ("camera 0 light 0",),
            status=1,
            prepare=truncate_chunk,
            stdout=True,
        ),
        Case(
            "verify: a store holding NaN",
            ("verify", "{tmp}/field.zarr", "--quiet"),
            ("non-finite",),
            status=1,
            prepare=nan_radiance,
            stdout=True,
        ),
    ]
    # rig process
    process = ("process", "{tmp}/dataset", "-o", "{tmp}/f.zarr")
    cases += [
        Case(
            "process: missing dataset", ("process", "{tmp}/none", "-o", "{tmp}/f.zarr"), ("none",)
        ),
        Case(
            "process: a deleted image",
            process,
            ("missing", "--allow-missing"),
            prepare=delete_image,
        ),
        Case("process: a cut image", process, ("corrupt",), prepare=corrupt_image),
        Case("process: an emptied journal", process, ("journal",), prepare=empty_journal),
        Case(
            "process: two images swapped, checksums re-vouched",
            process,
            ("corrupt", "holds the image of", "swapped or renamed"),
            prepare=swapped_images,
        ),
        Case(
            "process: records naming each other's files",
            process,
            ("corrupt", "holds the image of", "swapped or renamed"),
            prepare=records_naming_each_others_files,
        ),
        Case(
            "process: another dataset's journal",
            process,
            ("journal.jsonl belongs to another dataset", OTHER_DATASET, "put back"),
            prepare=another_datasets_journal,
        ),
        Case(
            "process: another dataset's manifest",
            process,
            ("manifest.json belongs to another dataset", OTHER_DATASET, "put back"),
            prepare=another_datasets_manifest,
        ),
        Case(
            "process: a light moved in the plan",
            process,
            ("differs from the plan the dataset was captured with", "lights[1] was"),
            prepare=moved_light,
        ),
        Case(
            "process: a journal line nested 200,000 deep",
            process,
            ("journal.jsonl, line 2", "JSON nested too deeply"),
            prepare=deep_journal_line,
        ),
        Case(
            "process: an existing output",
            ("process", "{dataset}", "-o", "{tmp}/field.zarr"),
            ("field.zarr", "--overwrite"),
            prepare=copy_field,
        ),
        Case(
            "process: -o a non-empty folder",
            ("process", "{dataset}", "-o", "{tmp}/taken"),
            ("taken", "not a field store"),
            prepare=an_output_folder,
        ),
        Case(
            "process: missing --points",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--points", "{tmp}/none.ply"),
            ("none.ply",),
        ),
        Case(
            "process: --points not a cloud",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--points", F + "points.npz"),
            ("points.npz",),
        ),
        Case(
            "process: zero-byte --points",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--points", F + "zero.npz"),
            ("zero.npz",),
        ),
        Case(
            "process: --scene teapot",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--scene", "teapot"),
            ("teapot",),
        ),
        Case(
            "process: --size 0x0",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--size", "0x0"),
            ("--size",),
        ),
        Case(
            "process: --spacing 0",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--spacing", "0"),
            ("--spacing",),
        ),
        Case(
            "process: --camera-distance 0.5",
            ("process", "{dataset}", "-o", "{tmp}/f.zarr", "--camera-distance", "0.5"),
            ("inside the object",),
        ),
    ]
    # rig capture
    capture = (
        "capture",
        "--sim",
        "--quiet",
        "--speed",
        "50",
        "--size",
        "32",
        "--points",
        "1000",
        "--cameras",
        "2",
        "--lights",
        "2",
    )
    cases += [
        Case("capture: nothing to run", ("capture", "-o", "{tmp}/d"), ("--sim", "--config")),
        Case(
            "capture: --sim --scene teapot",
            (*capture, "--scene", "teapot", "-o", "{tmp}/d"),
            ("teapot",),
        ),
        Case("capture: --cameras 0", (*capture, "--cameras", "0", "-o", "{tmp}/d"), ("--cameras",)),
        Case("capture: --size 0", (*capture, "--size", "0", "-o", "{tmp}/d"), ("--size",)),
        Case(
            "capture: --exposure-ms 1e12",
            (*capture, "--exposure-ms", "1e12", "-o", "{tmp}/d"),
            ("--exposure-ms", "an hour"),
        ),
        Case(
            "capture: --speed 1e-9",
            (*capture, "--speed", "1e-9", "-o", "{tmp}/d"),
            ("--speed", "between 0.01 and 1000"),
        ),
        Case(
            "capture: --exposure-ms -1",
            (*capture, "--exposure-ms", "-1", "-o", "{tmp}/d"),
            ("--exposure-ms",),
        ),
        Case(
            "capture: -o an existing dataset",
            (*capture, "-o", "{dataset}"),
            ("dataset", "resume it"),
        ),
        Case("capture: -o a file", (*capture, "-o", F + "existing.txt"), ("existing.txt",)),
        Case("capture: --resume a missing one", ("capture", "--resume", "{tmp}/none"), ("none",)),
        Case("capture: --resume a non-dataset", ("capture", "--resume", "{tmp}"), ("manifest",)),
        Case(
            "capture: --resume an emptied journal",
            ("capture", "--resume", "{tmp}/dataset"),
            ("journal",),
            prepare=empty_journal,
        ),
        Case(
            "capture: --resume a manifest nested 200,000 deep",
            ("capture", "--resume", "{tmp}/dataset", "--quiet"),
            ("manifest.json", "JSON nested too deeply"),
            prepare=deep_manifest,
        ),
        Case(
            "capture: --resume a journal line nested 200,000 deep",
            ("capture", "--resume", "{tmp}/dataset", "--quiet"),
            ("journal.jsonl, line 2", "JSON nested too deeply"),
            prepare=deep_journal_line,
        ),
        Case(
            "capture: --resume with another dataset's journal",
            ("capture", "--resume", "{tmp}/dataset", "--quiet"),
            ("journal.jsonl belongs to another dataset", OTHER_DATASET, "put back"),
            prepare=another_datasets_journal,
        ),
        Case(
            "capture: --resume with another dataset's manifest",
            ("capture", "--resume", "{tmp}/dataset", "--quiet"),
            ("manifest.json belongs to another dataset", OTHER_DATASET, "put back"),
            prepare=another_datasets_manifest,
        ),
        Case(
            "capture: --resume a light moved in the plan",
            ("capture", "--resume", "{tmp}/dataset", "--quiet"),
            ("differs from the plan the dataset was captured with", "start a new dataset"),
            prepare=moved_light,
        ),
        Case(
            "capture: --sim with --config",
            (*capture, "--config", "docs/rig.example.toml", "-o", "{tmp}/d"),
            ("--sim makes its own rig", "--config would be ignored", "not both"),
        ),
        Case(
            "capture: --sim with --plan",
            (*capture, "--plan", "docs/plan.example.toml", "-o", "{tmp}/d"),
            ("--sim makes its own rig", "--plan would be ignored", "not both"),
        ),
        Case(
            "capture: --resume with --sim --cameras 9",
            ("capture", "--resume", "{tmp}/dataset", "--sim", "--cameras", "9", "--quiet"),
            ("--resume", "--sim --cameras would be ignored", "drop them"),
            prepare=copy_dataset,
        ),
        Case(
            "capture: --cameras with --config and --plan",
            (
                "capture",
                "--config",
                "docs/rig.example.toml",
                "--plan",
                "docs/plan.example.toml",
                "--cameras",
                "9",
                "-o",
                "{tmp}/d",
            ),
            ("--cameras", "for --sim only"),
        ),
        Case(
            "capture: --resume another config",
            ("capture", "--resume", "{tmp}/dataset", "--config", "docs/rig.example.toml"),
            ("was captured with rig config", "would mix two set-ups"),
            prepare=copy_dataset,
        ),
        Case(
            "capture: missing --config",
            (
                "capture",
                "--config",
                "{tmp}/none.toml",
                "--plan",
                "docs/plan.example.toml",
                "-o",
                "{tmp}/d",
            ),
            ("none.toml",),
        ),
        Case(
            "capture: --plan not TOML",
            (
                "capture",
                "--config",
                "docs/rig.example.toml",
                "--plan",
                F + "bad.toml",
                "-o",
                "{tmp}/d",
            ),
            ("bad.toml",),
        ),
    ]
    # rig plan (each line whole, as typed: the table's repetition is deliberate, see above)
    cases += [
        Case(
            "plan: missing --config",
            ("plan", "--config", "{tmp}/none.toml", "--plan", "docs/plan.example.toml"),
            ("none.toml",),
        ),
        Case(
            "plan: config not TOML",
            ("plan", "--config", F + "bad.toml", "--plan", "docs/plan.example.toml"),
            ("bad.toml",),
        ),
        Case(
            "plan: zero-byte plan",
            ("plan", "--config", "docs/rig.example.toml", "--plan", F + "zero.toml"),
            ("zero.toml",),
        ),
        Case(
            "plan: a path step of 1e-12",
            ("plan", "--config", "{tmp}/step.toml", "--plan", "docs/plan.example.toml"),
            ("step.toml", "path_step_deg = 1e-12", "[0.001, 90]"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: an axis limit of -1e308",
            ("plan", "--config", "{tmp}/limit.toml", "--plan", "docs/plan.example.toml"),
            ("limit.toml", "min_deg", "ten turns"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: a feed of 1e-300 deg/min",
            ("plan", "--config", "{tmp}/feed.toml", "--plan", "docs/plan.example.toml"),
            ("feed.toml", "feed_deg_min", "0.01"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: an exposure of 1e308 ms",
            ("plan", "--config", "docs/rig.example.toml", "--plan", "{tmp}/exposure.toml"),
            ("exposure.toml", "exposures_ms[0]", "an hour"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: 50,000 exposures a pose",
            ("plan", "--config", "docs/rig.example.toml", "--plan", "{tmp}/many.toml"),
            ("many.toml", "50000 exposures", "at most 32"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: a range of +-1e308",
            ("plan", "--config", "docs/rig.example.toml", "--plan", "{tmp}/range.toml"),
            ("range.toml", "gives more than"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: a step of 5e-324",
            ("plan", "--config", "docs/rig.example.toml", "--plan", "{tmp}/tiny.toml"),
            ("tiny.toml", "gives more than"),
            prepare=hostile_numbers,
        ),
        Case(
            "plan: a 100000 x 100000 layout",
            ("plan", "--config", "docs/rig.example.toml", "--plan", F + "huge-plan.toml"),
            ("huge-plan.toml", "90000000 poses", "at most"),
        ),
        Case(
            "plan: --advise a missing field",
            ("plan", "--advise", "{tmp}/none.zarr", "--env", pano),
            ("none.zarr",),
        ),
        Case("plan: --advise without --env", ("plan", "--advise", "{field}"), ("--env",)),
        Case("plan: nothing", ("plan",), ("--config",)),
    ]
    # rig advise
    advise = ("advise", "{field}", "--env", pano)
    cases += [
        Case("advise: missing field", ("advise", "{tmp}/none.zarr", "--env", pano), ("none.zarr",)),
        Case("advise: --tolerance 0", (*advise, "--tolerance", "0"), ("--tolerance",)),
        Case("advise: --samples 0", (*advise, "--samples", "0"), ("--samples",)),
        Case(
            "advise: zero-byte env",
            ("advise", "{field}", "--env", F + "zero.hdr"),
            ("zero.hdr", "empty"),
        ),
        Case(
            "advise: --json a directory",
            (*advise, "--json", "{tmp}/taken"),
            ("taken", "directory"),
            prepare=an_output_folder,
        ),
    ]
    # rig export-lp
    cases += [
        Case(
            "export-lp: missing dataset", ("export-lp", "{tmp}/none", "-o", "{tmp}/lp"), ("none",)
        ),
        Case(
            "export-lp: -o an existing file",
            ("export-lp", "{dataset}", "-o", F + "existing.txt"),
            ("existing.txt", "not a directory"),
        ),
        Case(
            "export-lp: -o under a file",
            ("export-lp", "{dataset}", "-o", F + "existing.txt/lp"),
            ("existing.txt", "not a directory"),
        ),
    ]
    # rig calibrate
    cases += [
        Case("calibrate: missing dataset", ("calibrate", "{tmp}/none"), ("none",)),
        Case(
            "calibrate: no calibration captures",
            ("calibrate", "{dataset}", "--dry-run"),
            ("calibration",),
        ),
        Case(
            "calibrate: --board 0x0",
            ("calibrate", "{dataset}", "--board", "0x0"),
            ("--board", "0x0"),
        ),
        Case(
            "calibrate: --board abc",
            ("calibrate", "{dataset}", "--board", "abc"),
            ("--board", "abc"),
        ),
        Case(
            "calibrate: --dictionary NOPE",
            ("calibrate", "{dataset}", "--dictionary", "NOPE"),
            ("NOPE",),
        ),
        Case(
            "calibrate: --sphere-radius 0",
            ("calibrate", "{dataset}", "--sphere-radius", "0"),
            ("--sphere-radius",),
        ),
    ]
    # rig doctor
    cases += [
        Case("doctor: missing --config", ("doctor", "--config", "{tmp}/none.toml"), ("none.toml",)),
        Case("doctor: config not TOML", ("doctor", "--config", F + "bad.toml"), ("bad.toml",)),
        Case(
            "doctor: --exposure-ms -5",
            ("doctor", "--config", "docs/rig.example.toml", "--exposure-ms", "-5"),
            ("--exposure-ms",),
        ),
    ]
    # rig sim
    cases += [
        Case(
            "sim start: missing --config",
            ("sim", "start", "--config", "{tmp}/none.toml"),
            ("none.toml",),
        ),
        Case(
            "sim start: --write-config a directory",
            ("sim", "start", "--write-config", "{tmp}/taken"),
            ("taken", "directory"),
            prepare=an_output_folder,
        ),
        Case(
            "sim start: --write-config an existing file",
            ("sim", "start", "--write-config", F + "existing.txt"),
            ("existing.txt", "exists"),
        ),
        Case(
            "sim field: --lights 0", (*field, "--lights", "0", "-o", "{tmp}/f.zarr"), ("--lights",)
        ),
        Case(
            "sim field: --scene teapot",
            (*field, "--scene", "teapot", "-o", "{tmp}/f.zarr"),
            ("teapot",),
        ),
        Case(
            "sim field: --distance 0.5",
            (*field, "--distance", "0.5", "-o", "{tmp}/f.zarr"),
            ("inside the object",),
        ),
        Case(
            "sim field: an existing store",
            (*field, "-o", "{tmp}/field.zarr"),
            ("field.zarr", "--overwrite"),
            prepare=copy_field,
        ),
        Case(
            "sim field: --size 100000x100000",
            (*field, "--size", "100000x100000", "-o", "{tmp}/f.zarr"),
            ("--size",),
        ),
        Case(
            "sim field: --points 10^12",
            (*field, "--points", "1000000000000", "-o", "{tmp}/f.zarr"),
            ("1000000000000",),
        ),
        Case("sim render: -o .png", (*render[:-2], "-o", "{tmp}/gt.png"), ("gt.png", ".exr")),
        Case("sim render: --grid -1", (*render, "--grid", "-1"), ("--grid",)),
        Case(
            "sim render: zero-byte env",
            (
                "sim",
                "render",
                "--scene",
                "glossy-sphere",
                "--env",
                F + "zero.exr",
                "--view",
                "0,30",
                "-o",
                "{tmp}/gt.exr",
            ),
            ("zero.exr", "empty"),
        ),
        Case("sim render: --view 0", (*render, "--view", "0"), ("--view",)),
        Case(
            "sim photo: --light bad", (*photo, "--light", "x,y", "-o", "{tmp}/p.png"), ("--light",)
        ),
        Case("sim photo: -o .bmp", (*photo, "-o", "{tmp}/p.bmp"), ("p.bmp",)),
        Case(
            "sim photo: --exposure-time 0",
            (*photo, "--exposure-time", "0", "-o", "{tmp}/p.png"),
            ("--exposure-time",),
        ),
        Case(
            "sim photo: --light-distance 0.5",
            (*photo, "--light-distance", "0.5", "-o", "{tmp}/p.png"),
            ("light", "0.5"),
        ),
        Case(
            "sim photo: -o a directory",
            (*photo, "-o", "{tmp}/out.png"),
            ("out.png", "directory"),
            prepare=an_output_folder,
        ),
    ]
    # rig evaluate and rig relight --lights
    evaluate = ("evaluate", "{field}", "--quiet")
    cases += [
        Case(
            "evaluate: missing field",
            ("evaluate", "{tmp}/none.zarr", "--split", "rings"),
            ("none.zarr", "no such"),
        ),
        Case(
            "evaluate: neither --test nor --split",
            evaluate,
            ("one of the arguments --test --split is required",),
        ),
        Case(
            "evaluate: unknown split", (*evaluate, "--split", "halves"), ("unknown split 'halves'",)
        ),
        Case(
            "evaluate: unknown method",
            (*evaluate, "--split", "rings", "--methods", "splines"),
            ("--methods", "splines"),
        ),
        Case(
            "evaluate: missing test .lp",
            (*evaluate, "--test", "{tmp}/none.lp"),
            ("none.lp", "no such"),
        ),
        Case(
            "evaluate: a test that is neither",
            (*evaluate, "--test", F + "existing.txt"),
            ("existing.txt", ".lp file or a field store"),
        ),
        Case(
            "evaluate: a mask on points",
            (*evaluate, "--split", "rings", "--mask", F + "text.png"),
            ("a mask applies to a field of pixels",),
        ),
        Case(
            "evaluate: too few lights to split",
            ("evaluate", "{tmp}/four.zarr", "--split", "every-other"),
            ("each side needs 3 or more",),
            prepare=four_light_field,
        ),
        Case(
            "evaluate: --json a folder",
            (*evaluate, "--split", "rings", "--json", "{tmp}/taken"),
            ("taken", "directory"),
            prepare=an_output_folder,
        ),
        Case(
            "relight --lights: missing .lp",
            ("relight", "{field}", "--lights", "{tmp}/none.lp", "-o", "{tmp}/out"),
            ("none.lp", "no such"),
        ),
        Case(
            "relight --lights: with --env too",
            ("relight", "{field}", "--lights", F + "sky.exr", "--env", pano, "-o", "{tmp}/out"),
            ("--env PANORAMA", "--lights FILE.lp"),
        ),
        Case(
            "relight --lights: points without --camera",
            ("relight", "{field}", "--lights", "{tmp}/two.lp", "-o", "{tmp}/out"),
            ("--camera INDEX",),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: --camera 9",
            ("relight", "{field}", "--lights", "{tmp}/two.lp", "--camera", "9", "-o", "{tmp}/out"),
            ("--camera 9", "0..2"),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: an entry escaping -o",
            (
                "relight",
                "{field}",
                "--lights",
                "{tmp}/escape.lp",
                "--camera",
                "0",
                "-o",
                "{tmp}/out",
            ),
            ("would be written outside",),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: two entries to one file",
            ("relight", "{field}", "--lights", "{tmp}/same.lp", "--camera", "0", "-o", "{tmp}/out"),
            ("would both be written to",),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: an entry named .",
            ("relight", "{field}", "--lights", "{tmp}/dot.lp", "--camera", "0", "-o", "{tmp}/out"),
            ("names no file",),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: an entry with a NUL byte",
            ("relight", "{field}", "--lights", "{tmp}/nul.lp", "--camera", "0", "-o", "{tmp}/out"),
            ("control character",),
            prepare=two_lights_lp,
        ),
        Case(
            "relight --lights: -o a file",
            (
                "relight",
                "{field}",
                "--lights",
                "{tmp}/two.lp",
                "--camera",
                "0",
                "-o",
                F + "existing.txt",
            ),
            ("existing.txt", "not a directory"),
            prepare=two_lights_lp,
        ),
    ]
    # path-traced worlds
    cases += [
        Case(
            "sim field: unknown world",
            (*field, "--renderer", "mitsuba", "--scene", "nowhere", "-o", "{tmp}/f.zarr"),
            ("unknown world 'nowhere'",),
        ),
        Case(
            "sim rti: unknown world",
            ("sim", "rti", "--scene", "nowhere", "-o", "{tmp}/d"),
            ("unknown world 'nowhere'",),
        ),
        Case(
            "sim rti: a world file with a bad shape",
            ("sim", "rti", "--scene", F + "bad.toml", "-o", "{tmp}/d"),
            ("bad.toml",),
        ),
        Case(
            "sim rti: -o a non-empty folder",
            ("sim", "rti", "--scene", "matte-relief", "-o", "{tmp}/taken"),
            ("taken", "not empty"),
            prepare=an_output_folder,
        ),
        Case(
            "sim rti: --spp 0",
            ("sim", "rti", "--scene", "matte-relief", "--spp", "0", "-o", "{tmp}/d"),
            ("--spp",),
        ),
    ]
    # rig bench and rig demo
    cases += [
        Case("bench: -o a file", ("bench", "--quick", "-o", F + "existing.txt"), ("existing.txt",)),
        Case("demo: -o a file", ("demo", "--quick", "-o", F + "existing.txt"), ("existing.txt",)),
        Case(
            "bench: --fields a file",
            ("bench", "--quick", "-o", "{tmp}/b", "--fields", F + "existing.txt"),
            ("existing.txt",),
        ),
    ]
    # rig view (refused before it serves) and rig export-web
    cases += _panorama_cases(("view", "{field}"), ("--env",))
    export = ("export-web", "{rti}", "-o", "{tmp}/web")
    cases += [
        Case("view: missing field", ("view", "{tmp}/none.zarr"), ("none.zarr", "no such")),
        Case("view: --port 70000", ("view", "{field}", "--port", "70000"), ("--port", "70000")),
        Case("view: --size 0x0", ("view", "{field}", "--size", "0x0"), ("--size",)),
        Case(
            "export-web: a field of points",
            ("export-web", "{field}", "-o", "{tmp}/web"),
            ("pixels",),
        ),
        Case("export-web: --camera 1", (*export, "--camera", "1"), ("--camera 1", "dirs.lp")),
        Case("export-web: --models rbf", (*export, "--models", "rbf"), ("rbf",)),
        Case("export-web: --quality 0", (*export, "--quality", "0"), ("quality",)),
        Case(
            "export-web: --format png --no-tiles",
            (*export, "--format", "png", "--no-tiles"),
            ("--format png --no-tiles", "plane_N.jpg"),
        ),
        Case(
            "export-web: --tile-size 64",
            (*export, "--tiles", "--tile-size", "64"),
            ("tile size 64", "64 pixels", "62"),
        ),
        Case(
            "export-web: --neural-holdout 0.5",
            (*export, "--neural-holdout", "0.5"),
            ("--neural-holdout", "0.5"),
        ),
        Case(
            "export-web: -o a file",
            ("export-web", "{rti}", "-o", F + "existing.txt"),
            ("existing.txt",),
        ),
    ]
    return cases


#: Every case of the sweep.
CASES: tuple[Case, ...] = tuple(_cases())


@contextlib.contextmanager
def _workspace_in(root: Path) -> Iterator[Workspace]:
    yield build_workspace(root)


def sweep(root: Path) -> Counter[str]:
    """Run every case in a workspace under ``root``; print each finding and the counts."""
    counts: Counter[str] = Counter()
    with _workspace_in(root / "workspace") as workspace:
        for number, case in enumerate(CASES):
            outcome = run_case(case, workspace, root / f"case-{number:03d}")
            counts[outcome.kind] += 1
            if outcome.kind != "clear":
                print(f"[{outcome.kind}] {case.name}: {outcome.detail}")
                print("    " + (outcome.err or outcome.out).strip().replace("\n", "\n    ")[:600])
    print(f"{len(CASES)} cases: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return counts


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as scratch:
        found = sweep(Path(scratch))
    sys.exit(0 if set(found) <= {"clear"} else 1)
