"""The learning table L[s, d] = alpha(s) * theta(d, s) of the paper's training schedule (section III)."""

from __future__ import annotations

import math

import numpy as np

from . import checks


def sigma_of(d_max: int) -> float:
    """sigma = d_max / sqrt(2 ln 2): theta falls to one half at d_max at the start of a run."""
    return d_max / math.sqrt(2.0 * math.log(2.0))


#: Entries of the table computed at once in float64 (8 MiB a temporary).
TABLE_BLOCK = 1 << 20


def learning_table(iterations: int, d_max: int, l_start: float = 0.25, l_end: float = 0.03) -> np.ndarray:
    """(S, d_max + 1) float32 table, computed in float64.

    alpha(s) = l_start * l_end / (l_end + (l_start - l_end) * s / S)        (learning rate)
    c(s) = sigma - sigma * s / S;  theta(d, s) = exp(-d^2 / (2 c(s)^2))     (neighbourhood)
    theta(0, s) = 1 always (also for d_max = 0, where c is 0).
    """
    S = checks.integer("iterations", iterations, 1)
    d_max = checks.integer("d_max", d_max, 0, 2**31 - 2)
    l_start = checks.real("l_start", l_start, 0.0, 1.0, low_open=True)
    l_end = checks.real("l_end", l_end, 0.0, 1.0, low_open=True)
    out = np.empty((S, d_max + 1), np.float32)
    d = np.arange(d_max + 1, dtype=np.float64)[None, :]
    sigma = sigma_of(d_max)
    rows = max(1, TABLE_BLOCK // (d_max + 1))  # float64 temporaries of a block, not of the whole table
    for start in range(0, S, rows):
        s = np.arange(start, min(S, start + rows), dtype=np.float64)[:, None]
        alpha = l_start * l_end / (l_end + (l_start - l_end) * s / S)
        c = sigma - sigma * s / S
        with np.errstate(divide="ignore", invalid="ignore"):
            theta = np.exp(-(d**2) / (2.0 * c**2))
        theta[:, 0] = 1.0
        theta = np.where(np.isfinite(theta), theta, 0.0)
        out[start:start + len(s)] = alpha * theta
    return out
