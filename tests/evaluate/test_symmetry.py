"""Symmetry cost (SPEC eqs 4.38-4.39) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.evaluate.measures import landmark_measures, region_lags
from physanim.evaluate.symmetry import displacement_curves, lag_frames, symmetry_cost

NAMES = ["ch_L", "ex_L", "pi_L", "al_L", "cphi_L", "ch_R", "ex_R", "pi_R", "al_R", "cphi_R"]


def face(stretch_left: float, stretch_right: float) -> np.ndarray:
    """Landmarks (10, 3): each side's points at unit distance from its cheilion, scaled."""
    pts = np.zeros((10, 3))
    pts[0], pts[5] = [0.03, 0, 0], [-0.03, 0, 0]
    dirs = np.array([[0, 1, 0], [0, 0.7, 0.7], [0, 0.5, 0.0], [-0.6, 0.8, 0]])
    pts[1:5] = pts[0] + 0.04 * stretch_left * dirs / np.linalg.norm(dirs, axis=1)[:, None]
    pts[6:10] = pts[5] + 0.04 * stretch_right * dirs / np.linalg.norm(dirs, axis=1)[:, None]
    return pts


def test_symmetric_motion_has_floor_cost_and_asymmetric_matches_hand_value() -> None:
    traj = np.stack([face(1, 1), face(1.1, 1.1), face(1.2, 1.05)])
    cost, e_l, e_r = symmetry_cost(traj, NAMES)
    np.testing.assert_allclose(e_l, [0, 0.4, 0.8], atol=1e-12)  # 4 landmarks x (s - 1)
    np.testing.assert_allclose(e_r, [0, 0.4, 0.2], atol=1e-12)
    assert cost[0] == cost[1] == pytest.approx(np.log(1e-12))
    assert cost[2] == pytest.approx(np.log(0.6))


def test_missing_landmark_is_named() -> None:
    with pytest.raises(ValueError, match="cphi_R"):
        symmetry_cost(np.zeros((2, 9, 3)), NAMES[:-1])


def test_displacement_and_lag() -> None:
    t = np.linspace(0, 1, 101)
    pts = np.zeros((101, 2, 3))
    pts[:, 0, 1] = np.sin(2 * np.pi * t) * 0.01
    pts[:, 1, 1] = np.roll(pts[:, 0, 1], 4)
    d = displacement_curves(pts)
    assert d.shape == (101, 2) and d[25, 0] == pytest.approx(0.01)
    assert lag_frames(pts[:, 0, 1], pts[:, 1, 1], 10) == pytest.approx(4, abs=0.01)
    pulse = lambda centre: np.exp(-(((np.arange(30) - centre) / 3.0) ** 2))  # noqa: E731
    # search range clamped to T - 1
    assert lag_frames(pulse(12), pulse(16), 50) == pytest.approx(4, abs=0.01)


def test_a_landmark_lost_in_some_frames_peaks_where_it_was_tracked() -> None:
    """Landmark 'a' moves 1 and 3 mm in frames 1 and 2 and is lost (NaN) in frame 3: it peaks
    at 3 mm in frame 2; landmark 'b', never tracked, peaks at NaN."""
    pts = np.zeros((4, 2, 3))
    pts[1:3, 0, 0] = [0.001, 0.003]
    pts[3, 0] = np.nan
    pts[:, 1] = np.nan
    both = np.concatenate([pts, np.stack([face(1, 1)] * 4)], axis=1)
    m = landmark_measures(both, ["a", "b", *NAMES])
    assert m.peak[0] == pytest.approx(0.003) and m.peak_frame[0] == 2
    assert np.isnan(m.peak[1])


def expression(t: np.ndarray, shift: float = 0.0) -> np.ndarray:
    """A smooth rise, hold and release (T,) over frames ``t``, delayed by ``shift`` frames."""
    x = t - shift
    return 1.0 / (1.0 + np.exp(-(x - 20.0) / 3.0)) - 1.0 / (1.0 + np.exp(-(x - 60.0) / 4.0))


@pytest.mark.parametrize("shift", [0.0, 0.37, -0.8, 1.55, 4.2])
def test_lag_frames_recovers_a_fractional_delay(shift: float) -> None:
    t = np.arange(90.0)
    assert lag_frames(expression(t), 0.3 * expression(t, shift), 10) == pytest.approx(
        shift, abs=0.01
    )


@pytest.mark.parametrize("tau_s", [0.0025, 0.025])
def test_a_kelvin_voigt_element_trails_its_load_by_its_time_constant(tau_s: float) -> None:
    """eta x' + E x = f(t): for a load slow against tau = eta / E the response trails it by
    tau (the low-pass phase delay, exact to O((omega tau)^2)); integrated exactly between the
    fine samples of a 30 fps capture and measured at 30 fps."""
    fps, sub = 30.0, 200
    fine = np.arange(90 * sub) / (fps * sub)
    load = expression(fine * fps)
    x, decay = np.zeros_like(load), np.exp(-1.0 / (fps * sub * tau_s))
    for i in range(1, len(fine)):  # exact for a load linear over each fine step
        step = load[i] - load[i - 1]
        x[i] = (
            load[i]
            - tau_s * step * fps * sub
            + decay * (x[i - 1] - load[i - 1] + tau_s * step * fps * sub)
        )
    lag_s = lag_frames(load[::sub], x[::sub], 10) / fps
    assert lag_s == pytest.approx(tau_s, rel=0.05)


def test_region_lags_per_region_and_none_where_nothing_moves() -> None:
    t = np.arange(60.0)
    reference = np.zeros((60, 3, 3))
    reference[:, :2, 0] = 0.004 * expression(t)[:, None]
    model = reference.copy()
    model[:, 0, 0] = 0.004 * expression(t, 0.5)
    model[:, 1, 0] = 0.004 * expression(t, 2.0)
    lags = region_lags(model, reference, np.array([0, 1, 2]), ["a", "b", "still"], 10, 1e-3)
    assert lags["a"] == pytest.approx(0.5, abs=0.01)
    assert lags["b"] == pytest.approx(2.0, abs=0.01)
    assert lags["still"] is None
    assert 0.5 < lags["overall"] < 2.0
