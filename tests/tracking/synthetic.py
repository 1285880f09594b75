"""Synthetic marker images drawn with exact, anti-aliased dots on a textured skin background."""

from __future__ import annotations

import numpy as np

SKIN = np.array([200.0, 150.0, 120.0])
DOT = np.array([0.22, 0.36, 0.42]) * 255.0


def draw(centres: np.ndarray, size=(480, 640), radius=2.5, seed=0, hidden=()) -> np.ndarray:
    """RGB uint8 image with dots at ``centres`` (K, 2) px (u, v); indices in ``hidden`` omitted."""
    h, w = size
    rng = np.random.default_rng(seed)
    vv, uu = np.mgrid[0:h, 0:w]
    shade = 0.75 + 0.25 * np.sin(uu / 37.0) * np.cos(vv / 53.0)  # smooth shading + texture
    img = SKIN[None, None, :] * shade[..., None] + rng.normal(0, 2.0, (h, w, 3))
    for k, (u, v) in enumerate(centres):
        if k in hidden:
            continue
        u0, v0 = int(u) - 6, int(v) - 6
        su, sv = np.meshgrid(np.arange(u0, u0 + 13), np.arange(v0, v0 + 13))
        cover = np.clip(radius + 0.5 - np.hypot(su - u, sv - v), 0.0, 1.0)  # anti-aliased disc
        patch = img[v0 : v0 + 13, u0 : u0 + 13]
        local = shade[v0 : v0 + 13, u0 : u0 + 13, None]
        img[v0 : v0 + 13, u0 : u0 + 13] = (1 - cover[..., None]) * patch + cover[
            ..., None
        ] * DOT * local
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def template(n=30, seed=0) -> np.ndarray:
    """A face-like 2D marker layout (K, 2) px: jittered grid, ~12 px apart at least."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(6), np.arange(5)), -1).reshape(-1, 2)[:n] * 28.0
    return g + rng.uniform(-6, 6, g.shape) - g.mean(axis=0)
