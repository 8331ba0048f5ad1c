"""Timing on a shared, noisy machine: keep the fastest of a few runs (standard library only,
so that scripts run by any Python can use it)."""
from __future__ import annotations

import math
import time


def best_of(repeat: int, fn):
    """(value of the fastest run, its wall time in s) over ``repeat`` runs of ``fn``."""
    best, value = math.inf, None
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        out = fn()
        elapsed = time.perf_counter() - start
        if elapsed < best:
            best, value = elapsed, out
    return value, best
