"""What the benchmark compares: the relighting methods of each study and the run configurations.

The ablation chain goes from the paper's configuration to per-sample models one change at a
time; the K sweep varies the sampled lights of three families; :class:`SuiteConfig` says which
scenes, environments, fields and studies one run measures (:data:`FULL`, :data:`QUICK`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from bench.suite.results import ConfigRecord, ModeRecord
from core.errors import InputError
from processing.interpolation import InterpolationMethod
from processing.sampling import SamplerName
from render.engines.interpolated import RelightSettings
from render.engines.models import ModelRelightSettings
from render.engines.modes import MOST_ACCURATE_MODELS, RelightMode
from render.light_prediction import PREDICTORS

__all__ = [
    "CHAIN_K",
    "FULL",
    "K_FAMILIES",
    "QUICK",
    "SCENES",
    "FieldSpec",
    "Method",
    "SuiteConfig",
    "ablation_methods",
    "config_record",
    "k_method",
    "mode_record",
]

#: (S cameras, T lights, surface points, image side in pixels) of a simulated field.
FieldSpec = tuple[int, int, int, int]

SCENES = ("diffuse-sphere", "glossy-sphere", "textured-torus")
#: The sampling of the paper and of our sampled schemes at the chain's steps.
CHAIN_K = 64


@dataclass(frozen=True)
class Method:
    """One relighting configuration of a study.

    Attributes
    ----------
    label : str, the name in tables and charts
    mode : RelightSettings or ModelRelightSettings
    role : "chain" (a step of the ablation chain, applied on top of the previous step) or
        "branch" (an alternative to the step before it, not carried on)
    """

    label: str
    mode: RelightMode
    role: str = "chain"


def ablation_methods(quick: bool = False) -> list[Method]:
    """The chain from the paper's configuration, one change per step, and its branches.

    Parameters
    ----------
    quick : bool, fewer branches (one sampler, no alternative interpolations)

    Returns
    -------
    list of Method, in chain order; branches follow the step they branch from
    """
    solid = RelightSettings(scheme="sampled", k=CHAIN_K)
    bary = replace(solid, interpolation="barycentric", view_interpolation="barycentric")
    samplers: tuple[SamplerName, ...] = (
        ("median-cut",) if quick else ("ostromoukhov", "cdf", "median-cut")
    )
    interpolations: tuple[InterpolationMethod, ...] = () if quick else ("nearest", "rbf")
    return [
        Method("paper", RelightSettings.paper_configuration(CHAIN_K)),
        Method("+ solid-angle weighting", solid),
        *(Method(f"  sampler {name}", replace(solid, sampler=name), "branch") for name in samplers),
        Method("+ barycentric lights & views", bary),
        *(
            Method(
                f"  interpolation {name}",
                replace(solid, interpolation=name, view_interpolation=name),
                "branch",
            )
            for name in interpolations
        ),
        Method("+ rearranged eq. 2 (pixels)", replace(bary, scheme="pixels")),
        Method("+ projection", replace(bary, scheme="projection")),
        Method(
            f"+ per-sample models, K={CHAIN_K}",
            ModelRelightSettings(lighting="sampled", k=CHAIN_K),
        ),
        Method("+ per-sample models, grid 64", MOST_ACCURATE_MODELS),
        # The interactive form of the last step (render.precomputed_lighting): on the chart
        # beside the exact grid sum it approximates.
        Method(
            "  models, precomputed lighting",
            replace(MOST_ACCURATE_MODELS, lighting="precomputed"),
            "branch",
        ),
    ]


#: The K sweep's families: the paper, our sampled scheme (chain step 4), models on K lights.
K_FAMILIES = ("paper", "sampled, barycentric", "models, sampled")


def k_method(family: str, k: int) -> Method:
    """The method of a K-sweep family at ``k`` lights.

    Parameters
    ----------
    family : str, one of :data:`K_FAMILIES`
    k : int, sampled lights

    Returns
    -------
    Method, labelled ``"{family} K={k}"``

    Raises
    ------
    InputError
        For an unknown family.
    """
    if family == "paper":
        mode: RelightMode = RelightSettings.paper_configuration(k)
    elif family == "sampled, barycentric":
        mode = RelightSettings(
            scheme="sampled", k=k, interpolation="barycentric", view_interpolation="barycentric"
        )
    elif family == "models, sampled":
        mode = ModelRelightSettings(lighting="sampled", k=k)
    else:
        raise InputError(f"unknown K family {family!r}")
    return Method(f"{family} K={k}", mode)


def mode_record(mode: RelightMode) -> ModeRecord:
    """A relighting mode as JSON: its engine and its settings' fields.

    Parameters
    ----------
    mode : RelightSettings or ModelRelightSettings

    Returns
    -------
    dict: ``engine`` ("models" or "relighter"), then every field of the settings
    """
    return {"engine": "models" if mode.uses_models else "relighter", **vars(mode)}


@dataclass(frozen=True)
class SuiteConfig:
    """What one run measures.

    Attributes
    ----------
    name : str, "full", "quick" or a test's own
    scenes : simulator scenes
    environments : environment names (see :func:`bench.suite.fields.environments`)
    chain_field : the field of the ablation chain and the K sweep
    density_fields : the other fields of the density sweep (the chain field is one more point)
    density_methods : labels of chain methods run on every density field
    quick_methods : the shorter chain (fewer branches)
    k_values, k_families : the K sweep
    repeats : timed frames per figure (after a warm-up frame)
    capture : (cameras, lights, image side) of the capture-overhead sweep, or None to skip
    loop : bool, whether to measure the product's interactive loop
    loop_field : (field, dtype) of the interactive loop (glossy sphere), or None for the chain
        field: a large field, so the loop's per-sample work is measured against the memory
        bandwidth it must stream
    sky_height : rows of the procedural sky
    advisor_fields, advisor_scenes, advisor_environments : where ``rig advise`` is validated
        (fields among the chain and density fields; HDR environments among ``environments``)
    advisor_samples : samples the advisor predicts on
    held_out_methods : the methods of the held-out-light study (:mod:`bench.held_out`);
        empty to skip it
    held_out_worlds, world_field : the path-traced worlds of that study (Mitsuba 3,
        :mod:`sim.world.mitsuba`) and their fields: (cameras, lights, image side, samples per
        pixel, points)
    rti_worlds, rti_capture : the worlds of that study captured as RTI domes: (fit lights,
        test lights, width, height, samples per pixel)
    advisor_worlds, advisor_world_field : path-traced worlds on which ``rig advise`` and every
        relighting configuration are scored against a path-traced truth under the real
        panoramas (:mod:`bench.advisor_world`), and their fields: (cameras, lights, image
        side, samples per pixel, points)
    """

    name: str
    scenes: tuple[str, ...]
    environments: tuple[str, ...]
    chain_field: FieldSpec
    density_fields: tuple[FieldSpec, ...]
    density_methods: tuple[str, ...]
    quick_methods: bool
    k_values: tuple[int, ...]
    k_families: tuple[str, ...]
    repeats: int
    capture: tuple[int, int, int] | None
    loop: bool = True
    loop_field: tuple[FieldSpec, str] | None = None
    sky_height: int = 256
    advisor_fields: tuple[FieldSpec, ...] = ()
    advisor_scenes: tuple[str, ...] = SCENES
    advisor_environments: tuple[str, ...] = ("courtyard", "sky")
    advisor_samples: int = 2000
    # Every rung, and the product's own choice among the quick ones (rig relight --lights
    # --fast; the learned rung's choice trains it three times: see bench.learned_study).
    held_out_methods: tuple[str, ...] = (*PREDICTORS, "auto-fast")
    held_out_worlds: tuple[str, ...] = ()
    world_field: tuple[int, int, int, int, int] = (8, 30, 96, 256, 8000)
    rti_worlds: tuple[str, ...] = ()
    rti_capture: tuple[int, int, int, int, int] = (49, 20, 128, 96, 256)
    advisor_worlds: tuple[str, ...] = ()
    advisor_world_field: tuple[int, int, int, int, int] = (30, 30, 64, 64, 3000)


def config_record(config: SuiteConfig) -> ConfigRecord:
    """``config`` as the results' ``config`` record, field by field.

    Parameters
    ----------
    config : SuiteConfig

    Returns
    -------
    ConfigRecord (its tuples are written to JSON as lists)
    """
    return {
        "name": config.name,
        "scenes": config.scenes,
        "environments": config.environments,
        "chain_field": config.chain_field,
        "density_fields": config.density_fields,
        "density_methods": config.density_methods,
        "quick_methods": config.quick_methods,
        "k_values": config.k_values,
        "k_families": config.k_families,
        "repeats": config.repeats,
        "capture": config.capture,
        "loop": config.loop,
        "loop_field": config.loop_field,
        "sky_height": config.sky_height,
        "advisor_fields": config.advisor_fields,
        "advisor_scenes": config.advisor_scenes,
        "advisor_environments": config.advisor_environments,
        "advisor_samples": config.advisor_samples,
        "held_out_methods": list(config.held_out_methods),
        "held_out_worlds": list(config.held_out_worlds),
        "world_field": list(config.world_field),
        "rti_worlds": list(config.rti_worlds),
        "rti_capture": list(config.rti_capture),
        "advisor_worlds": list(config.advisor_worlds),
        "advisor_world_field": list(config.advisor_world_field),
    }


_DENSITY_METHODS = (
    "paper",
    "+ barycentric lights & views",
    "+ rearranged eq. 2 (pixels)",
    "+ projection",
    "+ per-sample models, grid 64",
)

FULL = SuiteConfig(
    name="full",
    scenes=SCENES,
    environments=(
        "courtyard",
        "courtyard LDR",
        "studio",
        "studio LDR",
        "sky",
        "sky LDR",
    ),
    chain_field=(30, 30, 20_000, 128),
    # The dense light set keeps S = 30 and few points: 400 lights x 30 cameras of 20 000
    # points would be 2.9 GB and minutes of simulation for one more point on a chart.
    density_fields=((10, 10, 20_000, 128), (20, 20, 20_000, 128), (30, 400, 4_000, 96)),
    density_methods=_DENSITY_METHODS,
    quick_methods=False,
    k_values=(4, 16, 64, 256, 1024),
    k_families=K_FAMILIES,
    repeats=3,
    capture=(4, 6, 64),
    loop_field=((30, 30, 250_000, 512), "float16"),
    advisor_fields=((10, 10, 20_000, 128), (20, 20, 20_000, 128), (30, 30, 20_000, 128)),
    # A diffuse-like, a coloured metal and a layered coat, path-traced once (about 6 minutes
    # each, cached) at 256 samples per pixel: per-sample noise 0.6-2.8 % (docs/world.md).
    held_out_worlds=("matte-relief", "copper-bowl", "clearcoat-relief"),
    world_field=(8, 30, 96, 256, 8000),
    # RTI domes of the flat-ish worlds, 49 lights to fit and 20 to predict (about 2 minutes
    # each at 128 x 96 and 256 samples per pixel, cached).
    rti_worlds=("matte-relief", "clearcoat-relief", "brushed-knot"),
    # S = T = 30 under the real panoramas (about 3 minutes each to render at 64 x 64 and 64
    # samples per pixel, cached; 4 to score).
    advisor_worlds=("matte-relief", "copper-bowl"),
)

QUICK = SuiteConfig(
    name="quick",
    scenes=("glossy-sphere", "textured-torus"),
    environments=("courtyard", "courtyard LDR", "sky"),
    chain_field=(20, 20, 4_000, 64),
    density_fields=((10, 10, 4_000, 64),),
    density_methods=("paper", "+ barycentric lights & views", "+ per-sample models, grid 64"),
    quick_methods=True,
    k_values=(4, 64, 256),
    k_families=("paper", "models, sampled"),
    repeats=2,
    # Fewer images would measure the session's start-up, not the per-image overhead.
    capture=(4, 6, 64),
    advisor_fields=((20, 20, 4_000, 64),),
    advisor_scenes=("glossy-sphere",),
    advisor_environments=("courtyard",),
    advisor_samples=1000,
    held_out_worlds=("copper-bowl",),
    world_field=(4, 24, 64, 64, 3000),
    rti_worlds=("clearcoat-relief",),
    rti_capture=(49, 20, 64, 48, 64),
)
