"""Local polynomial regression against fields with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.tracking.local_fit import local_polynomial, polynomial_in_time

H, W, SIGMA = 60, 80, 3.0


def _field(coef: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """A quadratic c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 (H, W) over pixel centres,
    with a third of its pixels missing (NaN), and the mask of the valid ones."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    c = coef
    f = c[0] + c[1] * xs + c[2] * ys + c[3] * xs**2 + c[4] * xs * ys + c[5] * ys**2
    valid = np.random.default_rng(0).random((H, W)) > 0.33
    return np.where(valid, f, np.nan), valid


def _exact(coef: tuple[float, ...], uv: np.ndarray) -> np.ndarray:
    x, y = uv[:, 0], uv[:, 1]
    c = coef
    return c[0] + c[1] * x + c[2] * y + c[3] * x**2 + c[4] * x * y + c[5] * y**2


# points well inside the image, at sub-pixel positions
UV = np.random.default_rng(1).uniform([15, 15], [W - 15, H - 15], size=(200, 2))


def test_degree_two_reproduces_a_quadratic_over_missing_pixels():
    coef = (1.0, 0.02, -0.03, 0.004, -0.002, 0.003)
    values, valid = _field(coef)
    got = local_polynomial(values, valid, SIGMA, UV, degree=2)
    # float32 filters: the field reaches ~40, its round-off ~1e-5 of that
    np.testing.assert_allclose(got, _exact(coef, UV), atol=5e-4)


def test_degree_one_reproduces_a_plane_and_degree_zero_is_biased_by_curvature():
    plane = (2.0, 0.05, -0.04, 0.0, 0.0, 0.0)
    values, valid = _field(plane)
    np.testing.assert_allclose(
        local_polynomial(values, valid, SIGMA, UV, degree=1), _exact(plane, UV), atol=1e-3
    )
    bowl = (0.0, 0.0, 0.0, 0.01, 0.0, 0.01)  # Laplacian 0.04
    values, valid = _field(bowl)
    centres = np.rint(UV)  # degree 0 is read at the nearest pixel, as a constant
    mean = local_polynomial(values, valid, SIGMA, centres, degree=0)
    # a Gaussian mean of a bowl is lifted by sigma^2 / 2 times its Laplacian (0.18 here);
    # the missing pixels scatter it a little
    bias = mean - _exact(bowl, centres)
    assert abs(np.median(bias) - SIGMA**2 / 2 * 0.04) < 0.03
    quad = local_polynomial(values, valid, SIGMA, UV, degree=2)
    assert np.abs(quad - _exact(bowl, UV)).max() < 5e-3


def test_too_few_valid_pixels_give_nan():
    values, valid = _field((1.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    valid[:, : W // 2 + 10] = False
    left, right = np.array([[20.0, 30.0]]), np.array([[70.0, 30.0]])
    assert np.isnan(local_polynomial(values, valid, SIGMA, left, degree=2)[0])
    assert local_polynomial(values, valid, SIGMA, right, degree=2)[0] == pytest.approx(
        1.0, rel=1e-5
    )
    with pytest.raises(ValueError, match="degree"):
        local_polynomial(values, valid, SIGMA, right, degree=3)


def test_the_fit_over_time_follows_a_peak_the_gaussian_mean_flattens():
    """A vertex's motion peaking as a parabola in time, 3 mm high with second derivative
    -0.05 mm per frame^2: the Gaussian mean (degree 0) lowers the peak by sigma^2 / 2 times
    that (0.156 mm at 2.5 frames); the quadratic is exact everywhere, the sequence's cut
    windows at both ends included, and it leaves a quadratic in every vertex and axis."""
    t = np.arange(40, dtype=np.float64)
    peak = 3.0 - 0.025 * (t - 20.0) ** 2  # mm
    sigma = 2.5
    mean = polynomial_in_time(peak, sigma, degree=0)
    assert mean[20] - peak[20] == pytest.approx(-(sigma**2) / 2 * 0.05, rel=0.02)
    np.testing.assert_allclose(polynomial_in_time(peak, sigma, degree=2), peak, atol=1e-9)
    # (T, N, 3): each vertex and axis is smoothed along time alone
    rng = np.random.default_rng(2)
    coef = rng.normal(size=(3, 5, 3))
    motion = coef[0] + coef[1] * t[:, None, None] + coef[2] * 0.01 * t[:, None, None] ** 2
    smoothed = polynomial_in_time(motion.astype(np.float32), sigma, degree=2)
    assert smoothed.dtype == np.float32 and smoothed.shape == motion.shape
    np.testing.assert_allclose(smoothed, motion, atol=1e-4)
    # white noise comes out smaller (the point of smoothing), a line stays a line at degree 1
    noise = rng.normal(size=(200, 1000))
    assert polynomial_in_time(noise, sigma, degree=2)[20:-20].std() < 0.6
    np.testing.assert_allclose(polynomial_in_time(2.0 * t, sigma, degree=1), 2.0 * t, atol=1e-9)
    assert polynomial_in_time(peak, 0.0, degree=2) is peak
    with pytest.raises(ValueError, match="degree"):
        polynomial_in_time(peak, sigma, degree=3)
