"""Per-sample reflectance models fitted to a measured field, chosen by leave-one-light-out error.

Interpolating a reflectance field linearly between its T measured lights and S cameras (the
paper's eq. 1-3) blurs everything finer than the light spacing: a 30-light rig misses a GGX
lobe of roughness 0.2 by 13-20 %. Here every surface sample gets a small model fitted to all of
its measured values, and relighting goes through the model (:mod:`render.engines.models`). The
model of a field is chosen by its error on held-out measured lights (leave one light out,
"LOO"), never by ground truth, so the choice works on real captures too.

Models (``MODELS``)
-------------------
``lambert``
    f = rho_d / pi: RGB albedo. Point fields use the stored normal; pixel fields (one fixed
    view, RTI) a photometric-stereo normal.
``lambert+ggx``
    f = rho_d / pi + F0 D(h) G1(wi) G1(wo) / (4 cos(theta_i) cos(theta_o)): RGB albedo, RGB
    constant F0, GGX roughness alpha, separable Smith masking: the lobe of :mod:`core.brdf`,
    the simulator's model.
``ptm``, ``hsh2``, ``hsh3`` (pixel fields)
    Linear bases over the light direction in the camera frame: the 6-term biquadratic
    polynomial texture map (Malzbender et al. 2001) and hemispherical harmonics of order 2 and
    3 (4 and 9 terms, Gautron et al. 2004), one set of RGB coefficients per pixel.

Measured values are modelled as F[s, t, p] = f(l_t, v_sp) max(0, n_p . l_t) V[p, t]: l_t the
light, v_sp the direction from the sample toward camera s (the camera direction itself for a
pixel field, whose camera is distant), V the light's visibility (cast shadows).

Fitting the parametric models
-----------------------------
For a fixed alpha and normal the model is linear in (rho_d, F0), channel by channel, with the
same two basis values for R, G and B: a 2 x 2 non-negative least-squares problem per channel,
solved in closed form. Alpha is chosen by a log-spaced grid over ``ALPHA_RANGE`` then a golden
section search on log alpha around the best grid node. A lobe must be identified by the data:
some lit observation must see it at ``LOBE_PEAK`` of its peak or more (D(h) / D(n) >= 0.01:
a half vector within about 3 alpha of the normal; far in its tail D is proportional to
alpha^2, so only F0 alpha^2 would be fitted) and it must light at least ``MIN_LOBE_SUPPORT``
observations (the participation ratio of its basis values). Otherwise a needle lobe fits one
noisy value, or a tail fits noise with an arbitrary F0, and it shines wherever light comes
from directions no light was measured from. Measured on the glossy sphere (30 x 30) with 2 %
noise under the full courtyard, at a view between cameras: 12.8 % error without the peak
check, 0.89 / 0.43 / 0.35 / 0.49 / 0.71 % with LOBE_PEAK = 0.0003 / 0.003 / 0.01 / 0.1 / 0.5
(noise-free: 0.07 % at 0.01).

One view's lights also bound the lobe from below (:func:`lobe_alpha_range`, the default range
of a pixel field): its half vectors are about half the lights' spacing apart, and a lobe
narrower than that (alpha below ``LOBE_SPACING`` = 0.4 times the mean spacing in radians)
falls between them, so a noisy value or a missing light lets the search settle on a needle.
A 49-light Fibonacci dome seen from above, every other light held out (24 fit lights),
GGX alpha 0.2 with 2 % noise: the held-out lights' relative RMSE is 7.8 % with the bound,
26 % without (the median alpha is the same; a few pixels chose needles); alpha 0.15: 14 /
44 %. The cost is on lobes truly narrower than the bound: alpha 0.06, 69 % against 56 %.
Relit under the bundled panoramas against path-traced truth (``bench.env_truth --quick``,
the simulator's own scenes), the default's mean error went from 10.0 to 9.9 % and the
plastic-and-gold scene's 49-light sun from 16.1 to 12.4 %: the held-out choice had rejected
the model, whose every-other-light fit predicted a light near the highlight 66 % off.
A field of points is seen from several cameras, whose half vectors are denser: it keeps
``ALPHA_RANGE``.

Everything runs per sample in one numba kernel, parallel over samples, over all its
observations (every camera that sees it, every light).

Shadows. A shadowed value is ~0 where the unshadowed model predicts light. After a fit, the
best scale of the model for light t over the cameras, k_t = sum b m / sum m^2, says whether t
reached the sample: k_t < ``SHADOW_RATIO`` marks it shadowed and it leaves the fit; fit and
marks alternate until the marks settle (at most ``SHADOW_ITERATIONS`` fits). The marks are
kept as ``lit`` (P, T): 1 lit, 0 shadowed, 1 where the measurements carry no information (the
light is behind the sample's normal, or no camera sees the sample: the attached shadow is the
model's max(0, n . l), not V). Relighting interpolates ``lit`` to new light directions.

Pixel fields: the normal is first found by photometric stereo on luminance over each pixel's
middle-ranked lights (the darkest ``PS_DARK`` and brightest ``PS_BRIGHT`` fractions, likely
shadows and highlights, left out); with ``refine_normals`` a pattern search then moves it to
the model's least-squares optimum (the linear parameters re-solved at every step, alpha
between rounds: a coordinate descent).

Visibility beyond the measured lights (point fields). The marks are known at the T measured
lights only. :func:`with_geometric_visibility` completes them with shadow maps of the field's
own point cloud (:func:`geometric_shadow_marks`) at directions where no light was measured (or
everywhere), and :func:`shadow_mark_errors` says, on held-out measured lights, whether the
geometry or the interpolation of the other lights' marks predicts the measured marks better.

Leave one light out
-------------------
For each light t the model is refitted without light t (all its cameras) and predicts light t's
measured values; ``LooError`` sums the squared errors over every observation of a visible
sample (shadowed ones included) and the measured energy over the same observations, so every
model of a field and the interpolation baselines (:func:`interpolation_loo`) are scored on the
same values. Linear bases: the closed form e_i / (1 - h_ii) of the hat matrix. Parametric
models: the exact refit of (rho_d, F0) by removing light t's normal-equation terms, at the
fitted alpha, normal and shadow marks (so slightly optimistic); the held-out light's
visibility is the barycentric interpolation of the other lights' marks (it cannot be
measured, as at any new light direction).

:func:`choose_model` picks, per field or per sample, the simplest model whose LOO error is
within a tolerance of the best (a parsimony rule: models that fit equally well tie within
noise, and the simpler one extrapolates more safely).

Package layout (each module imports only those above it)
--------------------------------------------------------
``loo``         :class:`LooError`, the leave-one-out weights, the interpolation baselines
``fits``        the model names (``ModelName``) and the fitted models as data
``bases``       the linear bases and their hat-matrix fit
``stereo``      photometric stereo, a pixel field's starting normals (``PS_DARK``, ``PS_BRIGHT``)
``fit_kernel``  the numba kernel of the parametric fits (``LOBE_PEAK``, ``MIN_LOBE_SUPPORT``)
``layout``      the per-sample arrays of a fit, block by block (:class:`~.layout.FitLayout`)
``fitting``     :func:`fit_sample_models` (``ALPHA_RANGE``, :func:`lobe_alpha_range`,
                ``SHADOW_RATIO``, ``SHADOW_ITERATIONS``, :func:`sample_block_size`)
``shadows``     the geometric shadow marks
``choice``      :func:`choose_model` and the LOO table (``PARSIMONY_RELATIVE``, ...)
"""

from __future__ import annotations

from processing.sample_models.bases import evaluate_basis
from processing.sample_models.choice import (
    ModelChoice,
    ModelScore,
    choose_model,
    format_loo_table,
)
from processing.sample_models.fits import (
    BASIS_MODELS,
    MODELS,
    PARAMETRIC_MODELS,
    BasisFit,
    ParametricFit,
    SampleModels,
)
from processing.sample_models.fits import BasisModelName as BasisModelName
from processing.sample_models.fits import Fit as Fit
from processing.sample_models.fits import ModelName as ModelName
from processing.sample_models.fits import ParametricModelName as ParametricModelName
from processing.sample_models.fitting import (
    ALPHA_RANGE,
    LOBE_SPACING,
    budget_for,
    fit_sample_models,
    lobe_alpha_range,
    sample_block_size,
)
from processing.sample_models.loo import (
    LooError,
    interpolation_loo,
    leave_one_out_barycentric,
    leave_one_out_weights,
)
from processing.sample_models.shadows import (
    geometric_shadow_marks,
    shadow_mark_errors,
    with_geometric_visibility,
)
from processing.sample_models.stereo import photometric_stereo

__all__ = [
    "ALPHA_RANGE",
    "BASIS_MODELS",
    "LOBE_SPACING",
    "MODELS",
    "PARAMETRIC_MODELS",
    "BasisFit",
    "LooError",
    "ModelChoice",
    "ModelScore",
    "ParametricFit",
    "SampleModels",
    "budget_for",
    "choose_model",
    "evaluate_basis",
    "fit_sample_models",
    "format_loo_table",
    "geometric_shadow_marks",
    "interpolation_loo",
    "leave_one_out_barycentric",
    "leave_one_out_weights",
    "lobe_alpha_range",
    "photometric_stereo",
    "sample_block_size",
    "shadow_mark_errors",
    "with_geometric_visibility",
]
