"""The effective sweep width of the drone's camera, from the detection model: what IAMSAR track spacing rests on.

Search theory describes a sensor passing an object by its lateral range curve: the probability P(x) that one
straight pass detects an object at lateral distance x from the track. The effective sweep width is its integral,
W = integral of P(x) dx: as many objects are missed inside W as are detected outside it (Koopman; USCG, "The Theory
of Search: A Simplified Explanation", Soza & Company 1996; Larson, "Coast Guard Search & Rescue Metrics and
Definitions", 2005). IAMSAR plans parallel searches with a track spacing S from it and a coverage factor C = W / S
(IAMSAR Manual Vol. III, section "Sweep width, track spacing, and coverage"; C = 1 is the usual plan).

Here P(x) comes from the camera model of ``missions.search`` itself: one glimpse per decision step, every
``speed * step`` metres along the track, each detecting with the model's probability at that range, averaged over
where the first glimpse falls.
"""
from __future__ import annotations

import numpy as np

from missions import search

LATERAL_SAMPLES = 64
PHASE_SAMPLES = 8


def lateral_range_curve(lateral_m: np.ndarray, altitude_m: float, zoom: float, speed_mps: float, step_s: float,
                        size_m: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """(N, X) probability that one straight pass at ``speed_mps`` detects an object of size ``size_m`` (N,) and
    condition factor ``factor`` (N,) (``search.condition_factor``) at each lateral distance ``lateral_m`` (X,)."""
    half = float(search.footprint_half_width_m(altitude_m, zoom))
    spacing = max(speed_mps * step_s, 1e-3)
    along = np.arange(-half - spacing, half + spacing, spacing)  # glimpse positions along the track, one phase
    phases = (np.arange(PHASE_SAMPLES) + 0.5) / PHASE_SAMPLES * spacing
    n, x = len(size_m), np.asarray(lateral_m, dtype=np.float64)
    north, east = np.broadcast_arrays(phases[:, None, None] + along[None, None, :], x[None, :, None])
    objects = np.stack([north, east], axis=-1).reshape(1, -1, 2)  # (1, phases * X * glimpses, 2), drone at 0
    count = objects.shape[1]
    p = search.detection_probability_from_factors(np.zeros((n, 2)), np.repeat(objects, n, axis=0),
                                                  np.repeat(size_m[:, None], count, axis=1),
                                                  np.repeat(factor[:, None], count, axis=1), altitude_m, zoom, 1.0)
    missed = np.prod(1.0 - p.reshape(n, PHASE_SAMPLES, len(x), len(along)), axis=3)
    return 1.0 - missed.mean(axis=1)


def sweep_width_m(altitude_m: float, zoom: float, speed_mps: float, step_s: float, size_m: np.ndarray,
                  factor: np.ndarray) -> np.ndarray:
    """(N,) effective sweep width W (m): the integral of :func:`lateral_range_curve` over lateral distance."""
    half = float(search.footprint_half_width_m(altitude_m, zoom))
    x = np.linspace(-half, half, LATERAL_SAMPLES)
    curve = lateral_range_curve(x, altitude_m, zoom, speed_mps, step_s, size_m, factor)
    return np.trapezoid(curve, x, axis=1)
