"""Sub-pixel refinement of a stereo disparity map by local Lucas-Kanade matching.

Why: SGBM finds each pixel's disparity to 1/16 px by fitting a parabola to its matching cost
at the best whole disparity and its two neighbours, and that fit pulls the result towards
whole pixels ("pixel locking"). On the demo face at 0.48 m one pixel of disparity is 6.2 mm of
depth, so the lock is a depth error that follows the surface in bands and changes as the face
moves: dense capture reads it as motion. Neither OpenCV's SGBM nor its WLS filter removes it.

Method: with the rectified grey images L, R and the disparity d (x_right = x_left - d), each
iteration warps R to the left view, R_w(x) = R(x - d(x)), and moves d by the delta that best
explains the residual r = L - R_w in a Gaussian window about each pixel, under a local
brightness offset c between the cameras:

    min over delta, c of  sum_window w (r + delta g - c)^2,   g = (dR_w/dx + dL/dx) / 2,

    delta = -cov_w(r, g) / var_w(g)

(weighted covariances over the window's valid pixels). The window assumes a locally constant
disparity, which a Gaussian of ``sigma_px`` keeps close to the pixel. Each step is clipped to
half a pixel, the total change to ``max_shift_px``; pixels whose window has too little
horizontal texture keep SGBM's value.

Measured (``tests/capture/test_subpixel.py``, ``test_stereo_real.py``): on the demo face the
median disparity error falls from 0.12-0.13 px to 0.06-0.07 px; on the real Middlebury
"Motorcycle" pair from 0.178 to 0.166 px with two steps, while more steps drift there (4:
0.184 px, 8: 0.204 px; the local window has more variance than SGBM's smoothness-regularised
match once the lock is gone), hence two steps by default. Cost: about 30 ms per 640 x 480
frame, a quarter of the stereo ingest's time per frame (``benchmarks/bench_ingest.py``).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

#: smallest weighted variance of the horizontal gradient, (8-bit levels / px)^2, for a step
MIN_GRADIENT_VARIANCE = 1.0
#: largest step of one iteration, px
MAX_STEP_PX = 0.5


def _grey(image: NDArray) -> NDArray:
    """(H, W) float32 grey levels of an RGB (H, W, 3) or grey (H, W) uint8 image."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return grey.astype(np.float32)


def refine_disparity(
    left: NDArray,
    right: NDArray,
    disparity: NDArray,
    sigma_px: float,
    iterations: int,
    max_shift_px: float = 1.0,
) -> NDArray:
    """Disparity (H, W) float32 px of the rectified ``left`` and ``right`` images (H, W, 3)
    or (H, W) uint8, refined from ``disparity`` (H, W) px (NaN invalid, kept NaN) by
    ``iterations`` Lucas-Kanade steps over a Gaussian window of ``sigma_px`` (module
    docstring); no value moves by more than ``max_shift_px`` from its start."""
    if sigma_px <= 0 or iterations <= 0:
        return np.asarray(disparity, dtype=np.float32)
    left_g, right_g = _grey(left), _grey(right)
    valid = np.isfinite(disparity)
    start = np.where(valid, disparity, 0.0).astype(np.float32)
    d = start.copy()
    h, w = left_g.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    left_dx = cv2.Sobel(left_g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    right_dx = cv2.Sobel(right_g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    weight = valid.astype(np.float32)

    def window(values: NDArray) -> NDArray:
        return cv2.GaussianBlur(values * weight, (0, 0), sigma_px)

    total = window(np.ones_like(weight))
    for _ in range(iterations):
        map_x = xs - d
        warped = cv2.remap(right_g, map_x, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        warped_dx = cv2.remap(
            right_dx, map_x, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        g = 0.5 * (warped_dx + left_dx)
        r = left_g - warped
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_g, mean_r = window(g) / total, window(r) / total
            var_g = window(g * g) / total - mean_g**2
            cov = window(r * g) / total - mean_g * mean_r
            step = np.where(var_g > MIN_GRADIENT_VARIANCE, -cov / var_g, 0.0)
        step = np.clip(np.nan_to_num(step), -MAX_STEP_PX, MAX_STEP_PX)
        d = np.clip(d + step, start - max_shift_px, start + max_shift_px).astype(np.float32)
    return np.where(valid, d, np.nan).astype(np.float32)
