"""Over 500 lines because numba's cache sees only this file's edits: the kernels stay together.

The numba kernel of the parametric fits, parallel over samples.

Every sample's lambert / lambert+ggx fit, shadow marks, normal refinement and
leave-one-light-out error.

Why: numba's ``cache=True`` invalidates a cached kernel only when its own source file changes,
not when a jitted function or a global constant it calls from another file does. Keeping every
kernel and the constants they compile in here means an edit to any of them recompiles the whole
kernel instead of running a stale cache.
(``core.brdf``'s lobe, cosines and view direction are the jitted callees outside this file:
they are the one definition the shading kernels share; an edit there wants the cache cleared.)

The kernels pass a sample's observations as separate arrays (cosines, light of each, values),
so their argument lists repeat one another on purpose: numba kernels take arrays and scalars,
not the objects one would group them in.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from core.brdf import cosine, half_vector_cosine, specular_lobe, toward_eye

__all__ = ["fit_samples"]

#: A GGX lobe is identified when some lit observation sees it at this fraction of its peak or
#: more (D(h) / D(n)) and it lights at least MIN_LOBE_SUPPORT observations (participation
#: ratio (sum a)^2 / sum a^2 of its basis values); otherwise the fit drops it at that alpha.
LOBE_PEAK, MIN_LOBE_SUPPORT = 0.01, 3.0
#: Rounds of normal (at fixed alpha) then alpha refinement.
REFINE_ROUNDS = 3


@numba.njit(cache=True)
def _solve_pair(
    s11: float, s12: float, s22: float, r1: float, r2: float
) -> tuple[float, float, float]:
    # min x^T S x - 2 x . r over x >= 0 (2 unknowns): the interior optimum if feasible, else the
    # best one-variable optimum, else 0. Returns x1, x2 and the objective (<= 0).
    x1 = x2 = best = 0.0
    if s11 > 0.0 and r1 > 0.0 and -r1 * r1 / s11 < best:
        x1, x2, best = r1 / s11, 0.0, -r1 * r1 / s11
    if s22 > 0.0 and r2 > 0.0 and -r2 * r2 / s22 < best:
        x1, x2, best = 0.0, r2 / s22, -r2 * r2 / s22
    det = s11 * s22 - s12 * s12
    if det > 1e-12 * s11 * s22 and det > 0.0:
        y1 = (s22 * r1 - s12 * r2) / det
        y2 = (s11 * r2 - s12 * r1) / det
        if y1 >= 0.0 and y2 >= 0.0 and -(y1 * r1 + y2 * r2) < best:
            x1, x2, best = y1, y2, -(y1 * r1 + y2 * r2)
    return x1, x2, best


@numba.njit(cache=True)
def _geometry(
    normal: NDArray[np.float64],
    light_of: NDArray[np.int64],
    view_of: NDArray[np.int64],
    lights: NDArray[np.float64],
    views: NDArray[np.float64],
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
) -> None:
    # Cosines of every observation for one normal; cos_i = 0 marks an observation the model
    # predicts 0 (light or view behind the surface).
    n = (normal[0], normal[1], normal[2])
    for k in range(light_of.shape[0]):
        t, s = light_of[k], view_of[k]
        light = (lights[t, 0], lights[t, 1], lights[t, 2])
        view = (views[s, 0], views[s, 1], views[s, 2])
        ci, co = cosine(n, light), cosine(n, view)
        if ci <= 0.0 or co <= 0.0:
            cos_i[k] = cos_o[k] = cos_h[k] = 0.0
            continue
        cos_i[k], cos_o[k] = ci, co
        cos_h[k] = half_vector_cosine(n, light, view)


# Observations as separate arrays, as every kernel here takes them (module doc).
@numba.njit(cache=True)
def _objective(
    alpha: float,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> float:
    # Least-squares objective (minus the constant sum of b^2) over the lit observations at one
    # alpha; writes the per-channel solution (albedo in x1, F0 in x2).
    s11 = s12 = s22 = s2 = 0.0
    peak = 0.0
    a4 = alpha**4
    r1 = np.zeros(3)
    r2 = np.zeros(3)
    for k in range(cos_i.shape[0]):
        ci = cos_i[k]
        if ci <= 0.0 or lit[light_of[k]] <= 0.0:
            continue
        a1 = ci / math.pi
        a2 = 0.0
        if with_lobe:
            a2 = specular_lobe(ci, cos_o[k], cos_h[k], alpha) * ci
            d = cos_h[k] * cos_h[k] * (alpha * alpha - 1.0) + 1.0
            peak = max(peak, a4 / (d * d))  # D(h) / D(n)
        s11 += a1 * a1
        s12 += a1 * a2
        s22 += a2 * a2
        s2 += a2
        for c in range(3):
            r1[c] += a1 * values[k, c]
            r2[c] += a2 * values[k, c]
    if with_lobe and (peak < LOBE_PEAK or s2 * s2 < MIN_LOBE_SUPPORT * s22):
        # A lobe whose peak no observation sees (its far tail fixes only F0 alpha^2), or that
        # lights fewer than MIN_LOBE_SUPPORT observations (participation ratio), is not
        # identified: it would fit noise and shine wherever no light was measured from.
        s12 = s22 = 0.0
        r2[:] = 0.0
    total = 0.0
    for c in range(3):
        y1, y2, best = _solve_pair(s11, s12, s22, r1[c], r2[c])
        x1[c], x2[c] = y1, y2
        total += best
    return total


# Observations as separate arrays, as every kernel here takes them (module doc).
@numba.njit(cache=True)
def _best_alpha(
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> tuple[float, float]:
    # Alpha minimising the objective: the best node of the log grid, then golden section on
    # log alpha between its neighbours. Leaves x1, x2 at the returned alpha's solution.
    if not with_lobe:
        return 1.0, _objective(1.0, False, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    best, best_index = np.inf, 0
    for g in range(grid.shape[0]):
        value = _objective(grid[g], True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
        if value < best:
            best, best_index = value, g
    lo = math.log(grid[max(best_index - 1, 0)])
    hi = math.log(grid[min(best_index + 1, grid.shape[0] - 1)])
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a = hi - ratio * (hi - lo)
    b = lo + ratio * (hi - lo)
    fa = _objective(math.exp(a), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    fb = _objective(math.exp(b), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    for _ in range(golden_steps):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - ratio * (hi - lo)
            fa = _objective(math.exp(a), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
        else:
            lo, a, fa = a, b, fb
            b = lo + ratio * (hi - lo)
            fb = _objective(math.exp(b), True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    alpha = grid[best_index]
    if min(fa, fb) < best:
        alpha = math.exp(a) if fa < fb else math.exp(b)
    value = _objective(alpha, True, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    return alpha, value


# Observations as separate arrays, as every kernel here takes them (module doc).
@numba.njit(cache=True)
def _light_sums(
    alpha: float,
    with_lobe: bool,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    sums: NDArray[np.float64],
) -> None:
    # Per light t, over its observations: a1^2, a1 a2, a2^2 (columns 0-2), a1 b_c (3-5),
    # a2 b_c (6-8) over the observations the model lights, b_c^2 (9-11) over all of them.
    sums[:] = 0.0
    for k in range(cos_i.shape[0]):
        t = light_of[k]
        for c in range(3):
            sums[t, 9 + c] += values[k, c] * values[k, c]
        ci = cos_i[k]
        if ci <= 0.0:
            continue
        a1 = ci / math.pi
        a2 = specular_lobe(ci, cos_o[k], cos_h[k], alpha) * ci if with_lobe else 0.0
        sums[t, 0] += a1 * a1
        sums[t, 1] += a1 * a2
        sums[t, 2] += a2 * a2
        for c in range(3):
            sums[t, 3 + c] += a1 * values[k, c]
            sums[t, 6 + c] += a2 * values[k, c]


@numba.njit(cache=True, inline="always")
def _predicted_terms(
    sums: NDArray[np.float64], t: int, x1: NDArray[np.float64], x2: NDArray[np.float64]
) -> tuple[float, float]:
    # sum b m and sum m^2 of light t for the model x (m = x1 a1 + x2 a2), over RGB.
    cross = square = 0.0
    for c in range(3):
        cross += x1[c] * sums[t, 3 + c] + x2[c] * sums[t, 6 + c]
        square += (
            x1[c] * x1[c] * sums[t, 0]
            + 2.0 * x1[c] * x2[c] * sums[t, 1]
            + x2[c] * x2[c] * sums[t, 2]
        )
    return cross, square


@numba.njit(cache=True)
def _shadow_marks(
    sums: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
    ratio: float,
    lit: NDArray[np.float64],
) -> bool:
    # Mark light t shadowed when the model's best scale for it is below ``ratio``; lights
    # where the model predicts (almost) nothing carry no information and stay lit. Returns
    # whether any mark changed.
    t_count = sums.shape[0]
    largest = 0.0
    for t in range(t_count):
        largest = max(largest, _predicted_terms(sums, t, x1, x2)[1])
    changed = False
    for t in range(t_count):
        cross, square = _predicted_terms(sums, t, x1, x2)
        mark = 1.0
        if square > 1e-6 * largest and square > 0.0 and cross < ratio * square:
            mark = 0.0
        if mark != lit[t]:
            changed = True
        lit[t] = mark
    return changed


# Observations as separate arrays, as every kernel here takes them (module doc).
@numba.njit(cache=True)
def _fit_with_shadows(
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    ratio: float,
    iterations: int,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    light_of: NDArray[np.int64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    sums: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> tuple[float, float]:
    # Alternate fit and shadow marks until the marks settle; the result is the fit of the
    # final marks (``sums`` at its alpha).
    alpha, value = 1.0, 0.0
    for _ in range(iterations):
        alpha, value = _best_alpha(
            grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2
        )
        _light_sums(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, sums)
        if not _shadow_marks(sums, x1, x2, ratio, lit):
            return alpha, value
    alpha, value = _best_alpha(
        grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2
    )
    _light_sums(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, sums)
    return alpha, value


# Observations as separate arrays, as every kernel here takes them (module doc).
@numba.njit(cache=True)
def _refine_normal(
    normal: NDArray[np.float64],
    alpha: float,
    with_lobe: bool,
    light_of: NDArray[np.int64],
    view_of: NDArray[np.int64],
    lights: NDArray[np.float64],
    views: NDArray[np.float64],
    values: NDArray[np.float64],
    lit: NDArray[np.float64],
    first_step: float,
    min_step: float,
    cos_i: NDArray[np.float64],
    cos_o: NDArray[np.float64],
    cos_h: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
) -> None:
    # Pattern search on the normal (two tangent directions, halving steps) at fixed alpha and
    # shadow marks, the linear parameters re-solved at every candidate. Leaves ``normal`` and
    # the geometry at the best normal found.
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
    best = _objective(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
    step = first_step
    trial = np.empty(3)
    for _ in range(200):
        if step < min_step:
            break
        helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(normal, helper)
        u /= math.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2)
        w = np.cross(normal, u)
        improved = False
        for move in range(4):
            sign = 1.0 if move % 2 == 0 else -1.0
            axis = u if move < 2 else w
            for c in range(3):
                trial[c] = normal[c] + sign * step * axis[c]
            trial /= math.sqrt(trial[0] ** 2 + trial[1] ** 2 + trial[2] ** 2)
            _geometry(trial, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
            value = _objective(alpha, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit, x1, x2)
            if value < best - 1e-12 * abs(best):
                best = value
                normal[:] = trial
                improved = True
                break
        if not improved:
            step *= 0.5
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)


@numba.njit(cache=True)
def _leave_one_out(
    sums: NDArray[np.float64],
    lit: NDArray[np.float64],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
) -> tuple[float, float]:
    # Leave one light out: remove light t's terms from the normal equations, re-solve, predict
    # light t with the visibility interpolated from the other lights' marks. Returns the sum
    # of squared prediction errors and of squared measured values.
    s11 = s12 = s22 = 0.0
    r1 = np.zeros(3)
    r2 = np.zeros(3)
    t_count = sums.shape[0]
    for t in range(t_count):
        if lit[t] > 0.0:
            s11 += sums[t, 0]
            s12 += sums[t, 1]
            s22 += sums[t, 2]
            for c in range(3):
                r1[c] += sums[t, 3 + c]
                r2[c] += sums[t, 6 + c]
    y1 = np.zeros(3)
    y2 = np.zeros(3)
    loo = 0.0
    energy = 0.0
    for t in range(t_count):
        for c in range(3):
            if lit[t] > 0.0:
                y1[c], y2[c], _ = _solve_pair(
                    s11 - sums[t, 0],
                    s12 - sums[t, 1],
                    s22 - sums[t, 2],
                    r1[c] - sums[t, 3 + c],
                    r2[c] - sums[t, 6 + c],
                )
            else:
                y1[c], y2[c] = x1[c], x2[c]
        visible = 0.0
        for j in range(loo_indices.shape[1]):
            visible += loo_weights[t, j] * lit[loo_indices[t, j]]
        cross, square = _predicted_terms(sums, t, y1, y2)
        measured = sums[t, 9] + sums[t, 10] + sums[t, 11]
        loo += max(measured - 2.0 * visible * cross + visible * visible * square, 0.0)
        energy += measured
    return loo, energy


# The chunk's arrays one by one, as fit_samples hands them on (the note there).
@numba.njit(cache=True)
def _fit_sample(
    p: int,
    radiance: NDArray[np.float32],
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    distant: bool,
    lights: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    refine: bool,
    ratio: float,
    iterations: int,
    refine_steps: NDArray[np.float64],
    out_normal: NDArray[np.float64],
    out_x1: NDArray[np.float64],
    out_x2: NDArray[np.float64],
    out_alpha: NDArray[np.float64],
    out_lit: NDArray[np.uint8],
    out_loo: NDArray[np.float64],
    out_energy: NDArray[np.float64],
    out_fitted: NDArray[np.bool_],
) -> None:
    # Everything for sample p: gather its observations, fit with shadow marks, refine the
    # normal, leave each light out; writes row p of the outputs.
    s_count, t_count = radiance.shape[1], radiance.shape[2]
    # Observations of this sample: every (camera that sees it) x (light).
    n_obs = 0
    for s in range(s_count):
        if seen[p, s]:
            n_obs += t_count
    light_of = np.empty(n_obs, dtype=np.int64)
    view_of = np.empty(n_obs, dtype=np.int64)
    values = np.empty((n_obs, 3))
    views = np.zeros((s_count, 3))
    k = 0
    for s in range(s_count):
        if not seen[p, s]:
            continue
        views[s, 0], views[s, 1], views[s, 2] = toward_eye(points, p, eyes[s], distant)
        for t in range(t_count):
            light_of[k], view_of[k] = t, s
            for c in range(3):
                values[k, c] = radiance[p, s, t, c]
            k += 1
    normal = normals[p].copy()
    cos_i = np.zeros(n_obs)
    cos_o = np.zeros(n_obs)
    cos_h = np.zeros(n_obs)
    _geometry(normal, light_of, view_of, lights, views, cos_i, cos_o, cos_h)
    lit = np.ones(t_count)
    sums = np.zeros((t_count, 12))
    x1 = np.zeros(3)
    x2 = np.zeros(3)
    usable = False
    for j in range(n_obs):
        if cos_i[j] > 0.0:
            usable = True
            break
    out_fitted[p] = usable
    if not usable:
        out_normal[p] = normal
        out_lit[p, :] = 1
        energy = 0.0
        for j in range(n_obs):
            for c in range(3):
                energy += values[j, c] * values[j, c]
        out_loo[p] = energy  # predicted 0
        out_energy[p] = energy
        return
    alpha, _ = _fit_with_shadows(
        grid, golden_steps, with_lobe, ratio, iterations,
        cos_i, cos_o, cos_h, light_of, values, lit, sums, x1, x2,
    )  # fmt: skip
    if refine:
        # Coordinate descent: the normal at fixed alpha, then alpha at the new normal
        # (searching alpha at every trial normal costs 30 times more for the same optimum).
        for rounds in range(REFINE_ROUNDS):
            _refine_normal(
                normal, alpha, with_lobe, light_of, view_of, lights, views, values, lit,
                refine_steps[0] * 0.5**rounds, refine_steps[1],
                cos_i, cos_o, cos_h, x1, x2,
            )  # fmt: skip
            alpha, _ = _best_alpha(
                grid, golden_steps, with_lobe, cos_i, cos_o, cos_h, light_of, values, lit,
                x1, x2,
            )  # fmt: skip
        alpha, _ = _fit_with_shadows(
            grid, golden_steps, with_lobe, ratio, iterations,
            cos_i, cos_o, cos_h, light_of, values, lit, sums, x1, x2,
        )  # fmt: skip
    loo, energy = _leave_one_out(sums, lit, x1, x2, loo_indices, loo_weights)
    out_normal[p] = normal
    out_alpha[p] = alpha
    for c in range(3):
        out_x1[p, c], out_x2[p, c] = x1[c], x2[c]
    for t in range(t_count):
        out_lit[p, t] = lit[t]
    out_loo[p] = loo
    out_energy[p] = energy


# fit_samples repeats _fit_sample's argument list on purpose: numba kernels take arrays and
# scalars, not objects, and the parallel loop hands each sample's row to the serial fit.
@numba.njit(cache=True, parallel=True)
def fit_samples(
    radiance: NDArray[np.float32],
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    distant: bool,
    lights: NDArray[np.float64],
    loo_indices: NDArray[np.int64],
    loo_weights: NDArray[np.float64],
    grid: NDArray[np.float64],
    golden_steps: int,
    with_lobe: bool,
    refine: bool,
    ratio: float,
    iterations: int,
    refine_steps: NDArray[np.float64],
    out_normal: NDArray[np.float64],
    out_x1: NDArray[np.float64],
    out_x2: NDArray[np.float64],
    out_alpha: NDArray[np.float64],
    out_lit: NDArray[np.uint8],
    out_loo: NDArray[np.float64],
    out_energy: NDArray[np.float64],
    out_fitted: NDArray[np.bool_],
) -> None:
    """Fit one parametric model to every sample of a chunk, writing row p of each output.

    Parameters
    ----------
    radiance : ndarray, shape (P, S, T, 3), float32, the chunk's values, sample-major
    seen : ndarray, shape (P, S), bool, camera s sees sample p
    points : ndarray, shape (P, 3), float64, sample positions (zeros for a pixel field)
    normals : ndarray, shape (P, 3), float64, unit starting normals
    eyes : ndarray, shape (S, 3), float64, camera positions, or (``distant``) the unit view
        direction of the one distant camera
    distant : bool, the views are ``eyes`` themselves (pixel field), not eye - point
    lights : ndarray, shape (T, 3), float64, unit directions toward the measured lights
    loo_indices, loo_weights : ndarray, shape (T, k), int64 / float64, each light's visibility
        predicted from the others (:func:`processing.sample_models.leave_one_out_weights`)
    grid : ndarray, shape (G,), float64, alpha grid nodes, ascending
    golden_steps : int, golden-section steps after the grid
    with_lobe : bool, fit ``lambert+ggx`` (else ``lambert``)
    refine : bool, refine each normal by pattern search
    ratio : float, shadow ratio (a light whose best model scale is below it is shadowed)
    iterations : int, fits of the fit / shadow-mark alternation, at most
    refine_steps : ndarray, shape (2,), float64, first and smallest step (radians)
    out_normal : ndarray, shape (P, 3), float64, fitted unit normals
    out_x1, out_x2 : ndarray, shape (P, 3), float64, rho_d and F0 per channel
    out_alpha : ndarray, shape (P,), float64, GGX roughness (1 for ``lambert``)
    out_lit : ndarray, shape (P, T), float32, shadow marks (1 lit or unknown, 0 shadowed)
    out_loo, out_energy : ndarray, shape (P,), float64, LOO squared error and measured energy
        (squared field units)
    out_fitted : ndarray, shape (P,), bool, the sample had a usable observation

    A sample without one gets its starting normal, all-lit marks and an LOO error equal to its
    energy (predicted 0); its ``out_x1``, ``out_x2`` and ``out_alpha`` rows are not written.
    """
    # The per-sample work lives in _fit_sample: a small parallel loop compiles far faster.
    for p in numba.prange(radiance.shape[0]):
        _fit_sample(
            p, radiance, seen, points, normals, eyes, distant, lights, loo_indices, loo_weights,
            grid, golden_steps, with_lobe, refine, ratio, iterations, refine_steps, out_normal,
            out_x1, out_x2, out_alpha, out_lit, out_loo, out_energy, out_fitted,
        )  # fmt: skip
