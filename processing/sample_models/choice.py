"""Choosing a field's model by leave-one-light-out error, and the table of candidates' scores.

The choice follows the parsimony rule, per field or per sample.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from processing.sample_models.fits import SampleModels

__all__ = ["ModelChoice", "ModelScore", "choose_model", "format_loo_table"]

#: Parsimony: a simpler model is chosen when its LOO relative RMSE is within
#: best x (1 + rel) + abs of the best model's.
PARSIMONY_RELATIVE, PARSIMONY_ABSOLUTE = 0.05, 1e-3


@dataclass(frozen=True)
class ModelScore:
    """One row of the LOO table.

    Attributes
    ----------
    name : str, model (or interpolation scheme)
    loo_relative_rmse : float, over the whole field
    parameters : int, per sample
    chosen_share : float, share of samples that chose this model (per-sample choice), else 0/1
    """

    name: str
    loo_relative_rmse: float
    parameters: int
    chosen_share: float


@dataclass(frozen=True)
class ModelChoice:
    """The model(s) chosen by LOO error.

    Attributes
    ----------
    names : tuple of str, the candidate models, simplest first
    chosen : str, the model chosen for the whole field
    per_sample : ndarray, shape (P,), int8, or None
        Index into ``names`` of each sample's model (per-sample choice), None for one model.
    table : tuple of ModelScore, one per candidate, in ``names`` order
    """

    names: tuple[str, ...]
    chosen: str
    per_sample: NDArray[np.int8] | None
    table: tuple[ModelScore, ...]

    def sample_model(self, count: int) -> NDArray[np.int8]:
        """Index into ``names`` of each of ``count`` samples' model; shape (count,), int8."""
        if self.per_sample is not None:
            return self.per_sample
        return np.full(count, self.names.index(self.chosen), dtype=np.int8)


def choose_model(
    models: SampleModels,
    *,
    per_sample: bool = False,
    candidates: Sequence[str] | None = None,
    relative: float = PARSIMONY_RELATIVE,
    absolute: float = PARSIMONY_ABSOLUTE,
) -> ModelChoice:
    """Pick the model(s) by leave-one-light-out error, the simplest within a tolerance.

    A model is acceptable when its LOO relative RMSE is at most best x (1 + ``relative``) +
    ``absolute``; the acceptable one with the fewest parameters is chosen. Per sample, the same
    rule applies to each sample's own LOO errors (squared: e <= (sqrt(e_best) (1 + relative) +
    absolute sqrt(energy))^2).

    Parameters
    ----------
    models : SampleModels
    per_sample : bool, choose for each sample (else one model for the whole field)
    candidates : sequence of str, optional, fitted model names to choose among (default: every
        fitted model)
    relative, absolute : float, the parsimony tolerance (a ratio, and relative RMSE)

    Returns
    -------
    ModelChoice, the candidates ordered simplest first (parameters per sample, then given
    order); ``per_sample`` (P,) int8 when ``per_sample``

    Raises
    ------
    InputError
        No candidates, a candidate that was not fitted, a negative tolerance.
    """
    names = tuple(models.fits) if candidates is None else tuple(candidates)
    if not names:
        raise InputError("no candidate models to choose among")
    for name in names:
        models.fit(name)
    if relative < 0 or absolute < 0:
        raise InputError(f"parsimony tolerances must be >= 0, got {relative}, {absolute}")
    order = tuple(sorted(names, key=lambda n: (models.fits[n].parameters, names.index(n))))
    errors = {n: models.fits[n].loo.relative_rmse for n in order}
    best = min(errors.values())
    chosen = next(n for n in order if errors[n] <= best * (1.0 + relative) + absolute)
    choice: NDArray[np.int8] | None = None
    shares = {n: float(n == chosen) for n in order}
    if per_sample:
        squared = np.stack([models.fits[n].loo.squared_error for n in order])  # (M, P)
        energy = models.fits[order[0]].loo.energy
        limit = (np.sqrt(squared.min(axis=0)) * (1.0 + relative) + absolute * np.sqrt(energy)) ** 2
        choice = np.argmax(squared <= limit * (1.0 + 1e-12), axis=0).astype(np.int8)
        shares = {n: float(np.mean(choice == i)) for i, n in enumerate(order)}
    table = tuple(ModelScore(n, errors[n], models.fits[n].parameters, shares[n]) for n in order)
    return ModelChoice(names=order, chosen=chosen, per_sample=choice, table=table)


def format_loo_table(rows: Sequence[ModelScore], extra: Mapping[str, float] | None = None) -> str:
    """A Markdown table of LOO relative RMSE (models, then any ``extra`` named errors).

    Parameters
    ----------
    rows : sequence of ModelScore, e.g. ``ModelChoice.table``
    extra : mapping of name to relative RMSE (a ratio, shown in %), optional; rows without
        parameters or share, e.g. the interpolation baselines' :class:`LooError`

    Returns
    -------
    str, the table's lines joined by newlines (no trailing newline)
    """
    lines = [
        "| model | parameters / sample | LOO relative RMSE | chosen share |",
        "|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.name} | {row.parameters} | {100 * row.loo_relative_rmse:.2f} % | "
            f"{100 * row.chosen_share:.0f} % |"
        )
    for name, value in (extra or {}).items():
        lines.append(f"| {name} | - | {100 * value:.2f} % | - |")
    return "\n".join(lines)
