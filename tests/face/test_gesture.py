"""Exaggeration gestures over time (physanim.face.gesture): the factor follows the activity
of the named action units, so a smile gesture leaves the jaw drop alone."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.face.gesture import gesture_factors, unit_activity

NAMES = ["jaw_drop", "lip_corner_puller_L", "lip_corner_puller_R", "brow_lowerer"]


def test_activity_is_the_strongest_unit_scaled_from_rest_to_peak_to_the_fourth() -> None:
    au = np.array(
        [
            [0.0, 0.1, 0.2, 0.3],  # rest
            [0.9, 0.1, 0.2, 0.3],  # jaw drop: no smile
            [0.0, 0.5, 0.2, 0.3],  # half the left smile
            [0.0, 0.9, 0.6, 0.3],  # both at their peaks
            [0.0, 0.1, 0.4, 0.3],  # half the right smile
        ]
    )
    got = unit_activity(au, NAMES, ["lip_corner_puller_L", "lip_corner_puller_R"], 0.4)
    np.testing.assert_allclose(got, [0.0, 0.0, 0.0625, 1.0, 0.0625])
    assert np.all(unit_activity(au, NAMES, ["brow_lowerer"], 0.4) == 0.0)  # never moves: off
    assert np.all(unit_activity(au, NAMES, [], 0.4) == 0.0)


def test_a_leak_below_the_full_span_is_not_taken_for_the_expression() -> None:
    """A performance without a smile: the fit leaks 0.2 of a lip corner puller into its jaw
    drop. Scaled over its own range that leak would read as the smile's peak (1); over the
    full span of 0.4 units it reads (0.2 / 0.4)^4."""
    au = np.array([[0.0, 0.0, 0.1, 0.0], [0.9, 0.0, 0.3, 0.0], [0.0, 0.0, 0.1, 0.0]])
    units = ["lip_corner_puller_L", "lip_corner_puller_R"]
    np.testing.assert_allclose(unit_activity(au, NAMES, units, 0.4), [0.0, 0.0625, 0.0])
    np.testing.assert_allclose(unit_activity(au, NAMES, units, 0.2), [0.0, 1.0, 0.0])


def test_an_unknown_unit_is_named_with_the_fits_units() -> None:
    with pytest.raises(ValueError, match=r"\['smile'\].*lip_corner_puller_L"):
        unit_activity(np.zeros((3, 4)), NAMES, ["smile"], 0.4)


def test_factors_apply_in_full_at_the_peak_and_not_at_rest() -> None:
    factors = np.array([1.5, 1.0, 2.0])
    np.testing.assert_array_equal(gesture_factors(factors, None), factors)
    got = gesture_factors(factors, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(got, [[1.0, 1.0, 1.0], [1.25, 1.0, 1.5], [1.5, 1.0, 2.0]])
