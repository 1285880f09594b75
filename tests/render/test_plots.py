"""Evaluation plots: PNG + SVG written, non-trivial, labelled."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from physanim.render import plots

T = np.linspace(0.0, 1.0, 31)
BUMP = np.sin(np.pi * T)


def check(png, svg, *labels):
    img = cv2.imread(str(png))
    assert img is not None and img.shape[0] > 200 and img.std() > 10
    text = svg.read_text()
    for label in labels:
        assert label in text


def test_symmetry_cost(tmp_path):
    png, svg = plots.plot_symmetry_cost(
        T, {"model 1": np.log(1e-3 + BUMP), "model 2": np.log(1e-3 + 2 * BUMP)}, tmp_path / "s"
    )
    check(png, svg, "model 2", "log scale")


def test_mouth_corners_mm(tmp_path):
    png, svg = plots.plot_mouth_corners(
        T, {"model 1": np.c_[0.003 * BUMP, 0.002 * BUMP]}, tmp_path / "m"
    )
    check(png, svg, "displacement (mm)", "time (s)")


def test_energies_and_landmarks(tmp_path):
    energies = {"m1": {"kinetic": BUMP, "strain": BUMP**2, "dissipated": np.cumsum(BUMP)}}
    check(*plots.plot_energies(T, energies, tmp_path / "e"), "energy (J)", "dissipated")
    d = BUMP[:, None] * np.array([1e-3, 2e-3, 3e-3])
    check(*plots.plot_landmark_curves(T, d, ["ch_L", "ch_R", "pronasale"], tmp_path / "l"), "ch_R")


def test_shape_errors(tmp_path):
    with pytest.raises(ValueError, match="has 3 samples"):
        plots.plot_symmetry_cost(T, {"m": np.zeros(3)}, tmp_path / "s")
    with pytest.raises(ValueError, match=r"must be \(31, 2\)"):
        plots.plot_mouth_corners(T, {"m": np.zeros((31, 3))}, tmp_path / "m")
