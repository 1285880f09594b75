"""Local polynomial regression: of an image over its valid pixels, read at sub-pixel points
(:func:`local_polynomial`), and of a sequence over time (:func:`polynomial_in_time`).

A Gaussian-weighted mean (normalised convolution) of a field that curves is biased towards
its surroundings by about sigma^2 / 2 times its Laplacian: the depth change of lips pushed
towards the camera (a pucker) is flattened at its peak. A polynomial of degree 1 or 2 in the
pixel offsets, fitted by the same weights, removes that bias to first or second order
(Savitzky-Golay in two dimensions, with missing pixels); the price is more noise, so it wants
a wider window. The weighted moments are separable Gaussian-times-monomial filters
(OpenCV's ``sepFilter2D``), so the fit costs a few filters per image and one small solve per
point. Over time the same holds for an expression's peak, flattened by a Gaussian mean over
frames by about sigma^2 / 2 times its second derivative in time.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


def _monomials(degree: int) -> list[tuple[int, int]]:
    """Exponents (a, b) of the basis x^a y^b of a 2-D polynomial of ``degree``."""
    return [(a, b) for a in range(degree + 1) for b in range(degree + 1 - a)]


def local_polynomial(
    values: NDArray, valid: NDArray, sigma_px: float, uv: NDArray, degree: int
) -> NDArray:
    """Values (P,) at pixels ``uv`` (P, 2) (x, y) of the polynomial of ``degree`` (0-2) in
    the pixel offsets fitted, with Gaussian weights of ``sigma_px`` px, to ``values`` (H, W)
    over the ``valid`` (H, W) pixels. NaN where less than half the kernel's weight is valid
    or outside the image. The fit is centred on each point's nearest pixel and read at the
    point's offset from it, so degree 0 is the Gaussian-weighted mean at the nearest pixel."""
    if not 0 <= degree <= 2:
        raise ValueError(f"local_polynomial: degree must be 0, 1 or 2, got {degree}")
    r = int(np.ceil(3.0 * sigma_px))
    k = np.arange(-r, r + 1, dtype=np.float64)
    g = np.exp(-(k**2) / (2.0 * sigma_px**2))
    weight = valid.astype(np.float32)
    data = np.where(valid, values, 0.0).astype(np.float32)
    # the fit is centred on each point's nearest pixel and its polynomial read at the offset
    h, w = values.shape
    out = np.full(len(uv), np.nan)
    inside = np.isfinite(uv).all(axis=1)
    centre = np.rint(np.where(inside[:, None], uv, -1)).astype(np.int64)
    inside &= (centre[:, 0] >= 0) & (centre[:, 0] < w) & (centre[:, 1] >= 0) & (centre[:, 1] < h)
    col, row = centre[inside, 0], centre[inside, 1]
    offset = uv[inside] - centre[inside]

    def moment(image: NDArray, a: int, b: int) -> NDArray:
        # correlation: out(p) = sum_q g(q - p) (q - p)^(a, b) image(q)
        kx, ky = (g * k**a).astype(np.float32), (g * k**b).astype(np.float32)
        filtered = cv2.sepFilter2D(image, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)
        return filtered[row, col].astype(np.float64)

    basis = _monomials(degree)
    sums = {
        (a, b): moment(weight, a, b)
        for a, b in {(a1 + a2, b1 + b2) for a1, b1 in basis for a2, b2 in basis}
    }
    gram = np.stack([np.stack([sums[a1 + a2, b1 + b2] for a2, b2 in basis], -1)
                     for a1, b1 in basis], -2)  # fmt: skip
    rhs = np.stack([moment(data, a, b) for a, b in basis], -1)
    enough = gram[:, 0, 0] > 0.5 * g.sum() ** 2
    # a small ridge keeps one-sided windows (the edge of the valid pixels) solvable
    ridge = 1e-6 * gram[enough, :1, :1] * np.eye(len(basis))
    coef = np.linalg.solve(gram[enough] + ridge, rhs[enough][..., None])[..., 0]
    dx, dy = offset[enough, 0:1], offset[enough, 1:2]
    at = np.concatenate([dx**a * dy**b for a, b in basis], axis=1)
    fitted = np.full(int(inside.sum()), np.nan)
    fitted[enough] = (coef * at).sum(axis=1)
    out[inside] = fitted
    return out


def polynomial_in_time(values: NDArray, sigma_frames: float, degree: int) -> NDArray:
    """``values`` (T, ...) smoothed along their first axis: at each frame t the value at t of
    the polynomial of ``degree`` (0-2) in the frame offset fitted, with Gaussian weights of
    ``sigma_frames`` over +-3 sigma, to the frames within the sequence (a window that a
    sequence's end cuts is fitted one-sided). Degree 0 is a Gaussian-weighted mean; degree 2
    follows a peak's curvature (Savitzky-Golay with Gaussian weights). ``sigma_frames`` 0
    returns ``values`` unchanged."""
    if not 0 <= degree <= 2:
        raise ValueError(f"polynomial_in_time: degree must be 0, 1 or 2, got {degree}")
    values = np.asarray(values)
    n = values.shape[0]
    if sigma_frames <= 0 or n < 2:
        return values
    half = int(np.ceil(3.0 * sigma_frames))
    # the (T, T) linear filter: row t holds the weights that give the fit's value at t
    weights = np.zeros((n, n))
    for t in range(n):
        frames = np.arange(max(0, t - half), min(n, t + half + 1))
        offset = (frames - t).astype(np.float64)
        g = np.exp(-(offset**2) / (2.0 * sigma_frames**2))
        basis = np.vander(offset, min(degree, len(frames) - 1) + 1, increasing=True)
        gram = basis.T @ (g[:, None] * basis)
        weights[t, frames] = np.linalg.solve(gram, basis.T * g)[0]
    flat = values.reshape(n, -1)
    return (weights @ flat).reshape(values.shape).astype(values.dtype, copy=False)
