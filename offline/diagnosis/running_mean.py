"""Centred running mean that keeps the signal's length."""
from __future__ import annotations

import numpy as np


def running_mean(x: np.ndarray, rows: int) -> np.ndarray:
    """Mean over `rows` rows centred on each row, as many values as `x` has. np.convolve's
    "same" mode returns as many as the longer input, so a recording shorter than the window
    (a damaged or truncated one) would come back padded to the window, misaligned with every
    mask over its rows: the window shrinks to the recording instead."""
    rows = max(1, min(rows, len(x)))
    return np.convolve(x, np.ones(rows) / rows, mode="same")
