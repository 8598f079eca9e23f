"""The layout of results.json: the records :mod:`bench.suite` writes and its report reads.

Every record is a ``TypedDict``, so the in-memory results and the JSON read back are the same
plain dicts and mypy checks each key on both sides. Sequences are typed ``Sequence`` where
the suite holds tuples and the JSON holds lists. The advisor's and the stability study's
records stay untyped dicts: their modules (:mod:`bench.advisor`, :mod:`bench.stability`) make
and format them as ``dict[str, Any]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal, NotRequired, TypedDict, TypeGuard

if TYPE_CHECKING:
    from bench.guard_advice import AdviceRecord
    from bench.held_out import HeldOutRecord

__all__ = [
    "AdvisorRecord",
    "CaptureRecord",
    "ConfigRecord",
    "EnvironmentRecord",
    "FieldRecord",
    "InteractiveRecord",
    "KRow",
    "LoopModeRecord",
    "LoopRecord",
    "Machine",
    "MachineRecord",
    "ModeRecord",
    "ProductRecord",
    "Row",
    "RowFigure",
    "Score",
    "ScoreMetric",
    "SpecRecord",
    "StabilityRecord",
    "SuiteResults",
    "is_k_row",
]

#: A relighting mode's settings as JSON: ``engine`` ("relighter" or "models") and the settings'
#: own fields, whichever they are (they belong to :mod:`render`, and nothing here reads them).
ModeRecord = dict[str, object]

#: One row of :func:`bench.advisor.validate_advisor` (typed there as a plain dict).
AdvisorRecord = dict[str, Any]

#: The stability study's results, :func:`bench.stability.run_stability` (a plain dict there).
StabilityRecord = dict[str, Any]

#: The scores :func:`bench.suite.report.aggregate.aggregate` averages.
ScoreMetric = Literal["relative_rmse", "sample_relative_rmse", "psnr_db", "ssim"]

#: The per-row figures the report averages over scenes.
RowFigure = Literal["precompute_s", "new_lighting_ms", "new_view_ms", "memory_MB"]


class SpecRecord(TypedDict):
    """A simulated field: its scene, S cameras, T lights, surface points and view side (px)."""

    scene: str
    S: int
    T: int
    points: int
    image: int


class FieldRecord(SpecRecord):
    """A field of the run, with its per-sample model fit's times and its radiance's size.

    ``models_fit_s`` is None when the fit was made by an earlier run without its time.
    """

    models_fit_s: float | None
    models_load_s: float
    field_MB: float


class Score(TypedDict):
    """The error of one relit image against the simulator's ground truth.

    ``environment`` is the lighting given, ``hdr`` the environment of the truth, ``view``
    "captured" or "between"; ``psnr_db`` is None for a perfect image.
    """

    environment: str
    hdr: str
    ldr: bool
    view: str
    relative_rmse: float
    sample_relative_rmse: float
    psnr_db: float | None
    ssim: float
    outside_fraction: float


class Row(SpecRecord):
    """One method measured on one field in one study ("ablation", "k" or "density").

    ``role`` is "chain" or "branch"; ``k`` the sampled lights (None when every panorama
    pixel lights); the models' times are None for interpolating methods.
    """

    label: str
    role: str
    mode: ModeRecord
    k: int | None
    precompute_s: float
    models_fit_s: float | None
    models_load_s: float | None
    new_lighting_ms: float
    new_view_ms: float
    memory_MB: float
    scores: list[Score]
    study: str


class KRow(Row):
    """A row of the K sweep, which also names its family."""

    family: str


def is_k_row(row: Row) -> TypeGuard[KRow]:
    """Whether ``row`` belongs to the K sweep (and so has a ``family``).

    Parameters
    ----------
    row : Row

    Returns
    -------
    bool
    """
    return row["study"] == "k"


class EnvironmentRecord(TypedDict):
    """An environment: the one whose truth it is scored against, and the panorama's source."""

    truth: str
    ldr: bool
    source: str


class ConfigRecord(TypedDict):
    """:class:`bench.suite.methods.SuiteConfig` as JSON (one key per field)."""

    name: str
    scenes: Sequence[str]
    environments: Sequence[str]
    chain_field: Sequence[int]
    density_fields: Sequence[Sequence[int]]
    density_methods: Sequence[str]
    quick_methods: bool
    k_values: Sequence[int]
    k_families: Sequence[str]
    repeats: int
    capture: Sequence[int] | None
    loop: bool
    loop_field: Sequence[Sequence[int] | str] | None
    sky_height: int
    advisor_fields: Sequence[Sequence[int]]
    advisor_scenes: Sequence[str]
    advisor_environments: Sequence[str]
    advisor_samples: int
    held_out_methods: Sequence[str]
    held_out_worlds: Sequence[str]
    world_field: Sequence[int]
    rti_worlds: Sequence[str]
    rti_capture: Sequence[int]
    advisor_worlds: Sequence[str]
    advisor_world_field: Sequence[int]


class Machine(TypedDict):
    """The machine and software, as found at the start of a run."""

    cpu_count: int | None
    load_average: list[float]
    platform: str
    processor: str
    python: str
    numpy: str
    numba: str
    opencv: str


class MachineRecord(Machine):
    """The machine with the run's load at its end and its resident memory."""

    load_average_end: list[float]
    peak_rss_MB: float
    rss_growth_MB: float


class CaptureRecord(TypedDict):
    """A capture sweep on the simulated rig and its field building.

    :func:`bench.capture.bench_capture`'s figures, with the capture's wall time and the seconds
    of field building per second of capture.
    """

    cameras: int
    lights: int
    images: int
    speed_factor: float
    image_size: int
    exit_status: str
    wall_s: dict[str, float]
    modelled_motion_s: float
    exposure_s: float
    camera_simulation_s: float
    controller_s: float
    controller_share_of_motion_and_exposure: float
    controller_ms_per_image: float
    process_s: float
    process_images_per_s: float
    capture_wall_s: float
    process_over_capture: float


class LoopModeRecord(TypedDict):
    """The interactive loop of one mode; the bandwidth floor only for interpolating engines."""

    mode: str
    settings: ModeRecord
    loop_new_lighting_ms: float
    loop_new_view_ms: float
    relight_compute_ms: float
    frame_budget_ratio: float
    error_vs_reference: float
    bandwidth_floor_ms: NotRequired[float]
    bandwidth_floor_ratio: NotRequired[float]


class InteractiveRecord(TypedDict):
    """One mode's interactive figures (``results.json``'s ``interactive``, keyed by mode).

    ``error_vs_reference`` is the relative RMSE of a frame against the same predictors with
    the panorama summed exactly into a 64 x 128 grid (0 for a mode that is its own reference).
    """

    new_lighting_ms: float
    new_view_ms: float
    error_vs_reference: float
    points: int
    settings: ModeRecord


class LoopRecord(SpecRecord):
    """The interactive loop on one field: the frame budget, the copy bandwidth, every mode."""

    frame_budget_ms: float
    copy_bandwidth_GBps: float
    modes: list[LoopModeRecord]


class ProductRecord(TypedDict, total=False):
    """The whole product's speed; each part only when the configuration asks for it."""

    capture: CaptureRecord
    loop: LoopRecord


class SuiteResults(TypedDict):
    """The whole of ``results.json``.

    ``chain`` lists the ablation chain's labels in order; ``ssim`` and ``memory`` say how
    those figures are measured; ``interactive`` is the loop's modes keyed by name (empty
    without the loop); ``wall_s`` is the run's duration.
    """

    config: ConfigRecord
    machine: MachineRecord
    chain_field: list[int]
    environments: dict[str, EnvironmentRecord]
    chain: list[str]
    k_families: list[str]
    density_methods: list[str]
    ssim: str
    memory: str
    fields: list[FieldRecord]
    rows: list[Row]
    advisor: list[AdvisorRecord]
    product: ProductRecord
    stability: StabilityRecord
    held_out: NotRequired[list[HeldOutRecord]]
    guard_advice: NotRequired[list[AdviceRecord]]
    interactive: dict[str, InteractiveRecord]
    wall_s: float
