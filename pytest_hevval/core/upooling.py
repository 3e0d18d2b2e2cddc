"""u-pooling: one statement over recordings made at different operating points.

Ferson, Oberkampf & Ginzburg ("Model validation and predictive capability for the thermal
challenge problem", Computer Methods in Applied Mechanics and Engineering 197, 2008) measure how
far a model's predictive distribution F lies from what was observed by the area between F and
the observations' empirical distribution. When every observation comes from a different
condition (a trip in winter, one on the motorway), each has its own prediction F_i, and the
observations cannot be pooled in physical units. u-pooling pools them on the probability scale
instead: each observation y_i becomes u_i = F_i(y_i). If the model's distributions are right,
the u_i are uniform on [0, 1] whatever the conditions, so the area between the empirical
distribution of all u_i and the uniform distribution is one validation metric for the whole
campaign: 0 when the model's distributions match, at most 0.5 when every observation lies beyond
everything it predicts.

Applied here (a choice of this project, not of the paper): for a time series the model's
prediction over a recording is the distribution of the values it produces over that recording
(its duty cycle), and the observations are the measured samples. So u = F_model(y_measured) per
sample, with mid-ranks for ties. A recording's u values are kept as their empirical distribution
function on :data:`U_GRID`, which pools exactly: the pooled function is the weighted mean of the
recordings' functions. Each recording weighs the same, so a long trip does not outvote a short
one made at another operating point.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = [
    "U_GRID",
    "area_to_uniform",
    "pool",
    "u_distribution",
    "u_distribution_of",
    "u_values",
]

FloatArray = npt.NDArray[np.float64]

#: Where a recording's distribution of u is kept; the area is integrated on it (trapezoids),
#: so it is exact to about 1 / (2 · (points − 1))² of the unit square.
U_GRID: FloatArray = np.linspace(0.0, 1.0, 101)


def u_values(observed: npt.ArrayLike, predicted: npt.ArrayLike) -> FloatArray:
    """F_predicted(observed) for every observed value; ties count half (mid-rank)."""
    model = np.sort(np.asarray(predicted, dtype=np.float64))
    values = np.asarray(observed, dtype=np.float64)
    if model.size == 0:
        raise ValueError("u values need at least one predicted value")
    below = np.searchsorted(model, values, side="left")
    at_or_below = np.searchsorted(model, values, side="right")
    return np.asarray((below + at_or_below) / (2.0 * model.size), dtype=np.float64)


def u_distribution(u: npt.ArrayLike) -> FloatArray:
    """The empirical distribution function of ``u`` evaluated on :data:`U_GRID`."""
    ordered = np.sort(np.asarray(u, dtype=np.float64))
    if ordered.size == 0:
        raise ValueError("a distribution of u needs at least one value")
    counts = np.searchsorted(ordered, U_GRID, side="right")
    return np.asarray(counts / ordered.size, dtype=np.float64)


def u_distribution_of(observed: npt.ArrayLike, predicted: npt.ArrayLike) -> FloatArray:
    """``u_distribution(u_values(observed, predicted))`` without a u per sample.

    u is a non-decreasing step function of the observed value that changes only at the model's
    values, so {y : u(y) ≤ g} is a half-line ending at a model value, open or closed. Finding
    that end for each of the grid's points and counting the observations on its left needs one
    sort of the prediction and a search of the observations in a table of grid size, not a sort
    of the observations and two searches in the prediction: 2.5 times faster at 6,000 samples.
    The u values are formed as :func:`u_values` forms them, so the result is bit for bit the same.
    """
    values, counts = np.unique(np.asarray(predicted, dtype=np.float64), return_counts=True)
    if values.size == 0:
        raise ValueError("u values need at least one predicted value")
    observations = np.asarray(observed, dtype=np.float64)
    if observations.size == 0:
        raise ValueError("a distribution of u needs at least one value")
    at_or_below = np.cumsum(counts)
    below = at_or_below - counts
    total = 2.0 * int(at_or_below[-1])
    # u just below each distinct model value, and u at it; they alternate, non-decreasing.
    gap_u = (below + below) / total
    point_u = (below + at_or_below) / total
    first_gap_above = np.searchsorted(gap_u, U_GRID, side="right")
    first_point_above = np.searchsorted(point_u, U_GRID, side="right")
    # The first step above g is a gap: the half-line ends at the model value before it,
    # included; else it is a model value itself, excluded.
    closed = first_gap_above <= first_point_above
    ends = values[
        np.where(closed, first_gap_above - 1, np.minimum(first_point_above, values.size - 1))
    ]
    size = U_GRID.size
    before = np.bincount(np.searchsorted(ends, observations, side="right"), minlength=size + 1)
    up_to = np.bincount(np.searchsorted(ends, observations, side="left"), minlength=size + 1)
    count = np.where(closed, np.cumsum(up_to)[:size], np.cumsum(before)[:size])
    # u ≤ 1 always: every observation, also those above the largest model value.
    count = np.where(U_GRID >= 1.0, observations.size, count)
    return np.asarray(count / observations.size, dtype=np.float64)


def pool(
    distributions: Sequence[npt.ArrayLike], weights: Sequence[float] | None = None
) -> FloatArray:
    """Pool recordings' distributions of u (equal weights unless given)."""
    if not distributions:
        raise ValueError("nothing to pool")
    stacked = np.asarray(distributions, dtype=np.float64)
    if stacked.ndim != 2 or stacked.shape[1] != U_GRID.size:
        raise ValueError(f"each distribution must have {U_GRID.size} points on U_GRID")
    w = np.ones(len(stacked)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(stacked),) or np.any(w < 0) or not w.sum() > 0:
        raise ValueError("weights must be one non-negative number per distribution, not all 0")
    return np.asarray(w @ stacked / w.sum(), dtype=np.float64)


def area_to_uniform(distribution: npt.ArrayLike) -> float:
    """Area between a distribution of u on :data:`U_GRID` and the uniform one (0 … 0.5)."""
    gap = np.abs(np.asarray(distribution, dtype=np.float64) - U_GRID)
    return float(np.sum((gap[1:] + gap[:-1]) * np.diff(U_GRID)) / 2.0)
