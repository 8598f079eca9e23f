"""The names of the methods that predict a field under a light it did not measure.

Their home in the library is :mod:`render.light_prediction` (what each method does, and
:func:`render.light_prediction.make_predictor`); the names live here, on the ground floor,
because ``rig``'s parsers offer them too (:mod:`app.cli.choices`) and must not import the
library to print ``--help``.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = ["PREDICTORS", "PredictorName"]

PredictorName = Literal[
    "nearest",
    "barycentric",
    "rbf",
    "ptm",
    "hsh2",
    "hsh3",
    "ptm-8bit",
    "hsh2-8bit",
    "hsh3-8bit",
    "lambert",
    "lambert+ggx",
    "lambert+residual",
    "lambert+ggx+residual",
    "adaptive",
    "relief",
    "learned",
    "learned+residual",
    "learned+relief",
    "learned+relief+residual",
    "light-stage+lambert+ggx",
]
#: Every method, the baselines first.
PREDICTORS: tuple[PredictorName, ...] = get_args(PredictorName)
