"""Small statistics shared by evaluations and benchmarks (Wilson intervals, quantile summaries)."""
from __future__ import annotations

import math

import numpy as np


def wilson_interval(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate (good for small samples and rates near 0 or 1)."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def quantiles(values, qs=(0.1, 0.25, 0.5, 0.75, 0.9)) -> dict[str, float | None]:
    """Named quantiles (p10, p25, ...) of a sample; None for an empty sample."""
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return {f"p{round(q * 100)}": None for q in qs}
    return {f"p{round(q * 100)}": float(np.quantile(values, q)) for q in qs}
