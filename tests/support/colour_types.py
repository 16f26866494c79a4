"""One 8-bit RGB image as the other colour types an image fit accepts (the same colours)."""

from __future__ import annotations

import numpy as np


def same_colours(image: np.ndarray) -> list[np.ndarray]:
    """``image`` (H, W, 3) uint8 as floats in [0, 1] (float64 and float32), 16-bit and RGBA."""
    rgba = np.concatenate([image, np.full(image.shape[:2] + (1,), 255, np.uint8)], axis=2)
    return [
        image / 255.0,
        image.astype(np.float32) / 255.0,
        image.astype(np.uint16) * 257,
        rgba,
    ]
