from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.brdf import brdf, ggx_distribution, shade_light, smith_g1, specular_lobe
from core.directions import direction_from_angles_deg, panorama_directions, panorama_solid_angles

UP = np.array([0.0, 0.0, 1.0])
angles = st.tuples(st.floats(0, 360), st.floats(0, 89))


@given(angles, angles, st.floats(0.05, 1.0))
def test_reciprocity(a: tuple[float, float], b: tuple[float, float], alpha: float) -> None:
    wi, wo = direction_from_angles_deg(*a), direction_from_angles_deg(*b)
    rho, f0 = [0.3, 0.5, 0.7], [0.2, 0.4, 0.9]
    np.testing.assert_allclose(brdf(UP, wi, wo, rho, f0, alpha), brdf(UP, wo, wi, rho, f0, alpha))


@pytest.mark.parametrize("alpha", [0.1, 0.2, 0.5, 1.0])
def test_ggx_is_normalised(alpha: float) -> None:
    theta = np.linspace(0, np.pi / 2, 200_001)
    integrand = ggx_distribution(np.cos(theta), alpha) * np.cos(theta) * np.sin(theta)
    assert 2 * np.pi * np.trapezoid(integrand, theta) == pytest.approx(1.0, rel=1e-4)


def _albedo(wo: np.ndarray, rho: float, f0: float, alpha: float) -> float:
    omega = panorama_directions(1024, 2048).reshape(-1, 3)
    area = panorama_solid_angles(1024, 2048).ravel()
    f = brdf(UP, omega, wo, [rho] * 3, [f0] * 3, alpha)[:, 0]
    return float(np.sum(f * np.maximum(omega @ UP, 0) * area))


@pytest.mark.parametrize("view_incl", [0.0, 30.0, 60.0])
def test_white_lambertian_reflects_everything(view_incl: float) -> None:
    # White furnace: rho_d = 1 under unit radiance everywhere reflects radiance 1.
    wo = direction_from_angles_deg(20.0, view_incl)
    assert _albedo(wo, 1.0, 0.0, 1.0) == pytest.approx(1.0, rel=1e-4)


def test_specular_albedo_known_value() -> None:
    # At alpha = 1, D = 1/pi and the normal-incidence albedo is the integral of c / (1 + c)
    # over c in [0, 1]: 1 - ln 2 (single scattering loses energy on rough surfaces).
    albedo = _albedo(direction_from_angles_deg(0.0, 0.0), 0.0, 1.0, 1.0)
    assert albedo == pytest.approx(1.0 - np.log(2.0), rel=1e-4)


@pytest.mark.parametrize("alpha", [0.1, 0.3, 0.6])
def test_specular_lobe_never_gains_energy(alpha: float) -> None:
    for incl in (0.0, 45.0, 75.0):
        assert _albedo(direction_from_angles_deg(0.0, incl), 0.0, 1.0, alpha) <= 1.0 + 1e-3


def test_values_at_normal_incidence() -> None:
    rho, f0, alpha = np.array([0.2, 0.5, 0.8]), np.array([0.1, 0.2, 0.3]), 0.25
    value = brdf(UP, UP, UP, rho, f0, alpha)
    np.testing.assert_allclose(value, rho / np.pi + f0 / (4 * np.pi * alpha**2))
    np.testing.assert_allclose(brdf(UP, UP, UP, rho, [0, 0, 0], 1.0), rho / np.pi)


def test_below_the_surface_is_dark() -> None:
    below = direction_from_angles_deg(0.0, 120.0)
    assert np.all(brdf(UP, below, UP, [1, 1, 1], [1, 1, 1], 0.5) == 0)
    assert np.all(brdf(UP, UP, below, [1, 1, 1], [1, 1, 1], 0.5) == 0)


def test_the_scalar_lobe_is_the_brdfs_specular_part() -> None:
    # The numba kernels (simulator, fits, relighting) evaluate specular_lobe; brdf is the
    # definition: F0 D G / (4 cos_i cos_o).
    rng = np.random.default_rng(1)
    for cos_i, cos_o, cos_h, alpha in rng.uniform(0.05, 1.0, size=(50, 4)):
        expected = ggx_distribution(cos_h, alpha) * smith_g1(cos_i, alpha) * smith_g1(cos_o, alpha)
        assert specular_lobe(cos_i, cos_o, cos_h, alpha) == pytest.approx(
            float(expected) / (4.0 * cos_i * cos_o), rel=1e-12
        )


@pytest.mark.parametrize("with_lobe", [True, False])
def test_shade_light_is_the_brdf_times_the_cosine(with_lobe: bool) -> None:
    # Every shading kernel (simulator, model relighting) calls shade_light: it must be brdf
    # times max(0, n . wi), below-surface directions included (zero), and the diffuse term
    # alone without the lobe (F0 = 0).
    rng = np.random.default_rng(7)
    count = 400
    n, wi, wo = rng.normal(size=(3, count, 3))
    n, wi, wo = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in (n, wi, wo))
    wi[:40] = n[:40]  # normal incidence, and the view straight on too for some
    wo[:20] = n[:20]
    rho, f0 = rng.uniform(0, 1, (2, count, 3))
    alpha = rng.uniform(0.02, 1.0, count)
    f0_used = f0 if with_lobe else np.zeros_like(f0)
    cos_i = np.einsum("pk,pk->p", n, wi)
    expected = brdf(n, wi, wo, rho, f0_used, alpha) * np.maximum(cos_i, 0.0)[:, None]
    got = np.zeros((count, 3))
    for p in range(count):
        vectors = [(float(v[p, 0]), float(v[p, 1]), float(v[p, 2])) for v in (n, wi, wo, rho, f0)]
        got[p] = shade_light(*vectors, float(alpha[p]), with_lobe)
    assert np.any(got == 0.0) and np.any(got > 0.0)  # both sides of the surface were drawn
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-300)
