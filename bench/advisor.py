"""Validation of ``rig advise`` on the simulator: predicted errors against the true ones.

The advisor (:mod:`render.advisor`) predicts each configuration's error from the field alone,
by holding out measured lights and cameras. Here every candidate also relights the whole field
and is scored against the simulator's ground truth at a captured view and at a view between
captured cameras (relative RMSE over the samples the view shows, the quantity the advisor
predicts). Called by :mod:`bench.suite` for each validation field; the report gets a table, a
chart of predicted against true error, and how often the advisor's choice really is within
the tolerance.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from bench.sim_truth import Truth, image_errors
from core.camera_model import PinholeCamera
from core.field_store import ReflectanceField
from processing.panorama import Panorama
from processing.sample_models import SampleModels
from render.advisor import Advisor
from render.engines.interpolated import RelitImage
from render.engines.modes import open_relighter

__all__ = ["TrueError", "advisor_chart", "format_advisor", "simulator_error", "validate_advisor"]

#: The tolerance the validation asks for.
TOLERANCE = 0.02


#: The true error of a relit image: (environment name, view name, image) -> relative RMSE
#: over the samples both it and the truth show.
TrueError = Callable[[str, str, RelitImage], float]


def simulator_error(truths: Mapping[tuple[str, str], Truth]) -> TrueError:
    """The true error against the simulator's ground truth of each (environment, view)."""

    def error(env: str, view: str, image: RelitImage) -> float:
        return float(image_errors(image, truths[(env, view)])["sample_relative_rmse"])

    return error


def validate_advisor(
    scene: str,
    field: ReflectanceField,
    models: SampleModels,
    views: Mapping[str, PinholeCamera],
    true_error: TrueError,
    panoramas: Mapping[str, Panorama],
    *,
    samples: int,
    tolerance: float = TOLERANCE,
) -> list[dict[str, Any]]:
    """Predicted and true error of every advisor candidate on one field, per environment.

    Parameters
    ----------
    scene : str, the scene (or world) of ``field``
    field : ReflectanceField; models : its fit (the candidates' models are chosen from it)
    views : view name to camera
    true_error : TrueError, scores a relit view (:func:`simulator_error`, or a path-traced
        truth's, :mod:`bench.advisor_world`)
    panoramas : environment name to panorama (HDR: the advisor cannot know what clipping
        removed)
    samples : int, samples the advisor predicts on

    Returns
    -------
    list of dict, one per environment and candidate
    """
    s_count, t_count, p_count = field.shape
    start = time.perf_counter()
    advisor = Advisor(field, samples=samples)
    rows: list[dict[str, Any]] = []
    engines = {c.name: open_relighter(field, c.mode, models) for c in advisor.candidates}
    for env, panorama in panoramas.items():
        advice = advisor.advise(panorama, tolerance)
        advise_s = time.perf_counter() - start
        for prediction in advice.predictions:
            engine = engines[prediction.candidate.name]
            engine.set_lighting(panorama)
            true = {}
            for view, camera in views.items():
                engine.set_view(camera)
                image = engine.render()
                true[view] = true_error(env, view, image)
            rows.append(
                {
                    "scene": scene,
                    "S": s_count,
                    "T": t_count,
                    "points": p_count,
                    "environment": env,
                    "candidate": prediction.candidate.name,
                    "chosen": advice.choice is prediction,
                    "tolerance": tolerance,
                    "predicted": prediction.error,
                    "predicted_terms": {
                        "lights": prediction.lights,
                        "views": prediction.views,
                        "lighting": prediction.lighting,
                    },
                    "predicted_frame_ms": prediction.frame_ms,
                    "true": true,
                    "advise_s": advise_s,
                }
            )
        start = time.perf_counter()
        chosen = [r for r in rows[-len(advice.predictions) :] if r["chosen"]]
        verdict = (
            f"{chosen[0]['candidate']}: predicted {chosen[0]['predicted']:.2%}, true "
            f"{max(chosen[0]['true'].values()):.2%}"
            if chosen
            else "no choice"
        )
        print(f"advisor   {scene:15s} S={s_count:<3d} T={t_count:<3d} {env:10s} {verdict}")
    return rows


def _worst_true(row: Mapping[str, Any]) -> float:
    return float(max(row["true"].values()))


def format_advisor(rows: list[dict[str, Any]], chart: str | None = "advisor.png") -> str:
    """The report's section on the advisor, computed from the validation rows."""
    if not rows:
        return ""
    ratios = np.array([r["predicted"] / max(_worst_true(r), 1e-6) for r in rows])
    conservative = float(np.mean(ratios >= 1.0))
    tolerance = rows[0]["tolerance"]
    out = [
        "## The advisor: predicted against true error",
        "",
        f"`rig advise` predicts each configuration's error from the field alone (holding out "
        f"measured lights and cameras, docs/advisor.md). Here every candidate also relit the "
        f"whole field and was scored against the ground truth (relative RMSE over the samples "
        f"shown; the worse of the captured and the between view). Over {len(rows)} candidate "
        f"predictions: predicted / true has median {np.median(ratios):.2f} (quartiles "
        f"{np.percentile(ratios, 25):.2f}-{np.percentile(ratios, 75):.2f}); the prediction is "
        f"at or above the truth in {conservative:.0%} of them.",
        "",
        f"The choice at tolerance {tolerance:.0%}: the fastest candidate predicted within it.",
        "",
        "| scene | S | T | environment | choice | predicted | true (captured / between) | "
        "truly within | most accurate candidate (true) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["scene"], r["S"], r["T"], r["environment"]), []).append(r)
    hits = choices = 0
    for (scene, s, t, env), group in groups.items():
        best = min(group, key=_worst_true)
        chosen = [r for r in group if r["chosen"]]
        if chosen:
            c = chosen[0]
            within = _worst_true(c) <= tolerance
            hits += within
            choices += 1
            cells = (
                f"{c['candidate']} | {c['predicted']:.2%} | {c['true']['captured']:.2%} / "
                f"{c['true']['between']:.2%} | {'yes' if within else 'no'}"
            )
        else:
            cells = "none predicted within | - | - | -"
        out.append(
            f"| {scene} | {s} | {t} | {env} | {cells} | {best['candidate']} "
            f"({_worst_true(best):.2%}) |"
        )
    out += [
        "",
        f"Of {choices} choices, {hits} are truly within {tolerance:.0%}; in "
        f"{len(groups) - choices} cases no candidate was predicted within it.",
        "",
    ]
    if chart:
        out += [f"![advisor: predicted against true error]({chart})", ""]
    return "\n".join(out)


def advisor_chart(rows: list[dict[str, Any]], path: Path) -> None:
    """Predicted against true error of every candidate (log-log, with y = x)."""
    figure, axis = plt.subplots(figsize=(6, 5))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        chosen = [r for r in rows if r["scene"] == scene]
        axis.scatter(
            [100 * _worst_true(r) for r in chosen],
            [100 * r["predicted"] for r in chosen],
            s=12,
            label=scene,
        )
    values = [100 * _worst_true(r) for r in rows] + [100 * r["predicted"] for r in rows]
    low, high = max(min(values), 1e-3), max(values)
    axis.plot([low, high], [low, high], color="black", linewidth=0.8, label="predicted = true")
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xlabel("true relative RMSE, % (worse of captured and between view)")
    axis.set_ylabel("predicted relative RMSE, %")
    axis.set_title("rig advise: predicted against true error")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
