"""Images for people: the target against the shadow."""

from __future__ import annotations

import numpy as np

# Overlay colours: where both agree, the shadow is dark grey; shadow where the target has none
# is red (excess); target the shadow misses is blue (missing); lit wall is white.
BOTH = (60, 60, 60)
EXCESS = (220, 50, 40)
MISSING = (40, 110, 230)
WALL = (255, 255, 255)


def overlay_image(target: np.ndarray, shadow: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: agreement dark grey, excess shadow red, missing target blue."""
    target, shadow = np.asarray(target, bool), np.asarray(shadow, bool)
    out = np.empty(target.shape + (3,), np.uint8)
    out[:] = WALL
    out[target & shadow] = BOTH
    out[shadow & ~target] = EXCESS
    out[target & ~shadow] = MISSING
    return out


def mask_image(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool -> uint8 black shape on white."""
    return np.where(np.asarray(mask, bool), 0, 255).astype(np.uint8)


def overlay_preview(target: np.ndarray, shadow: np.ndarray, height: int) -> np.ndarray:
    """(height, height * w / h, 3) uint8: a search snapshot's overlay, as progress.gif and the
    app's live preview show it. target (H, W) bool; shadow (h, w) float at the snapshot's
    resolution, in shadow where > 0.5. The target is brought to the shadow's size, then the
    overlay to ``height`` rows; nearest pixel both times, so pixels stay crisp."""
    from skimage.transform import resize

    small_target = resize(np.asarray(target, float), shadow.shape, order=0) > 0.5
    ov = overlay_image(small_target, shadow > 0.5)
    width = height * ov.shape[1] // ov.shape[0]
    return (resize(ov.astype(float) / 255, (height, width), order=0) * 255).astype(np.uint8)
