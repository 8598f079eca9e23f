"""The names the ``rig`` parsers offer as choices and defaults, without importing the library.

``rig --help`` and every sub-command's ``--help`` must answer at once, and the modules that own
these names (:mod:`processing.sampling`, :mod:`render.light_prediction`, ...) import numpy,
numba and zarr, seconds of start-up on a loaded machine. So the parsers take them from here,
a module of literals, and ``tests/app/cli/test_startup.py`` checks each against its owner: a
name added to the library and not here fails that test rather than going unoffered.
"""

from __future__ import annotations

#: :data:`render.light_prediction.PREDICTORS`: the methods that predict an unmeasured light;
#: the list is core's, read by the library and the parsers alike, so it is not restated here.
from core.predictor_names import PREDICTORS

__all__ = [
    "CHOSEN",
    "INTERPOLATIONS",
    "MODELS",
    "MODEL_GRID_HEIGHT",
    "PREDICTORS",
    "SAMPLERS",
    "SCHEMES",
    "SEQUENCES",
    "SPLITS",
    "WEB_MODELS",
    "WEB_NEURAL_SECONDS",
    "WEB_TILE_SIZE",
    "WEB_TILE_THRESHOLD",
]

#: :data:`processing.sampling.SAMPLERS`: the panorama samplers.
SAMPLERS = ("tmed", "ostromoukhov", "floyd-steinberg", "uniform", "cdf", "median-cut")

#: :data:`processing.interpolation.METHODS`: interpolation over measured lights or cameras.
INTERPOLATIONS = ("paper", "nearest", "barycentric", "rbf")

#: :data:`processing.sample_models.MODELS`: the per-sample models.
MODELS = ("lambert", "lambert+ggx", "ptm", "hsh2", "hsh3")

#: :data:`render.evaluation.CHOSEN`: the automatic choices ``rig evaluate`` also scores.
CHOSEN = ("auto", "auto-fast")

#: :data:`render.engines.interpolated.SCHEMES`: how a panorama lights a field (interpolation modes).
SCHEMES = ("sampled", "pixels", "projection")

#: :data:`render.light_splits.SPLITS`: the ways of holding out a field's own lights.
SPLITS = ("every-other", "rings", "random")

#: :data:`render.sequence.SEQUENCES`: what turns in a relit sequence.
SEQUENCES = ("environment", "turntable")

#: ``render.engines.modes.MOST_ACCURATE_MODELS.grid_height``: the grid the models sum a
#: panorama into by default.
MODEL_GRID_HEIGHT = 64

#: :data:`render.web_export.WEB_MODELS`: the models ``rig export-web`` writes.
WEB_MODELS = ("ptm", "hsh2", "hsh3", "neural")
#: :data:`render.web_export.TILE_SIZE`, ``TILE_THRESHOLD`` and ``NEURAL_SECONDS``: the
#: export's deep-zoom tile side, the side above which it tiles, the neural fit's budget (s).
WEB_TILE_SIZE = 254
WEB_TILE_THRESHOLD = 2048
WEB_NEURAL_SECONDS = 120.0
