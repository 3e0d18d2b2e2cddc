"""Hypothesis strategies shared by the tests of the maths."""

from __future__ import annotations

import numpy as np
from hypothesis import assume
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import signal as sps

from pytest_hevval.core.tree import TreeNode

__all__ = [
    "finite",
    "logged_channels",
    "quantised_pairs",
    "regression_terms",
    "signal_pairs",
    "signal_trees",
    "time_series",
    "time_series_of",
]

#: The kinds of series the diagnosis's statistics are checked on against statsmodels and arch.
SERIES_KINDS = ("persistent", "random_walk", "oscillating", "trending", "heavy_tailed")

#: Finite sample values over twelve orders of magnitude.
finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
#: The times of one to five calls of a model, in seconds.
call_times = st.lists(st.floats(0.01, 10.0), min_size=1, max_size=5)


@st.composite
def signal_pairs(
    draw: st.DrawFn, min_size: int = 3, max_size: int = 300
) -> tuple[np.ndarray, np.ndarray]:
    """An aligned (reference, simulated) pair whose reference is not constant."""
    n = draw(st.integers(min_size, max_size))
    reference = draw(hnp.arrays(np.float64, n, elements=finite))
    assume(np.ptp(reference) > 1e-6 * (np.abs(reference).max() + 1))
    simulated = draw(hnp.arrays(np.float64, n, elements=finite))
    return reference, simulated


@st.composite
def quantised_pairs(
    draw: st.DrawFn, min_size: int = 2, max_size: int = 60
) -> tuple[np.ndarray, np.ndarray]:
    """An aligned pair of quantised curves: a few levels, each often held for several samples,
    so that many warping paths cost exactly the same. The quantum is not a power of two, so
    sums of squared differences round, and the order they are summed in can break a tie."""
    n = draw(st.integers(min_size, max_size))
    quantum = draw(st.sampled_from([0.1, 0.3, 1 / 3, 0.7]))

    def curve() -> np.ndarray:
        hold = draw(st.integers(1, 6))
        levels = draw(hnp.arrays(np.int64, -(-n // hold), elements=st.integers(-4, 4)))
        return np.repeat(levels, hold)[:n] * quantum

    return curve(), curve()


@st.composite
def logged_channels(
    draw: st.DrawFn, min_size: int = 3, max_size: int = 400
) -> tuple[np.ndarray, np.ndarray]:
    """(time, values) of a logged channel without NaN: stretches of noise, of a held value
    (zero or not), of straight-line fill and at a clipped extreme, on a time base that may
    jump forward or back."""
    n = draw(st.integers(min_size, max_size))
    quantum = draw(st.sampled_from([0.0, 0.1, 0.25, 1 / 3]))
    pieces: list[np.ndarray] = []
    while sum(p.shape[0] for p in pieces) < n:
        length = draw(st.integers(1, 40))
        kind = draw(st.sampled_from(["noise", "hold", "zero", "ramp", "clip"]))
        if kind == "noise":
            piece = draw(hnp.arrays(np.float64, length, elements=st.floats(-50.0, 50.0)))
        elif kind == "hold":
            piece = np.full(length, draw(st.floats(-50.0, 50.0)))
        elif kind == "zero":
            piece = np.zeros(length)
        elif kind == "ramp":
            start, slope = draw(st.floats(-50.0, 50.0)), draw(st.floats(-2.0, 2.0))
            piece = start + slope * np.arange(length)
        else:
            piece = np.full(length, 60.0)
        pieces.append(piece)
    values = np.concatenate(pieces)[:n]
    if quantum:
        values = np.round(values / quantum) * quantum
    steps = draw(
        hnp.arrays(np.float64, n - 1, elements=st.sampled_from([0.1, 0.1, 0.1, 2.0, 0.0, -0.5]))
    )
    time = np.concatenate([[0.0], np.cumsum(steps)])
    return time, values


@st.composite
def signal_trees(draw: st.DrawFn, max_depth: int = 3, max_children: int = 3) -> TreeNode:
    """A validation tree of up to ``max_depth`` levels with random weights α and unique names."""
    counter = iter(range(10_000))

    def grow(depth: int) -> TreeNode:
        count = draw(st.integers(0, max_children)) if depth < max_depth else 0
        children = tuple(grow(depth + 1) for _ in range(count))
        alpha = draw(st.sampled_from([0.0, 0.5, 1.0, 2.0]))
        return TreeNode(f"s{next(counter)}", alpha, children)

    root = grow(1)
    return TreeNode(root.name, draw(st.sampled_from([0.5, 1.0, 3.0])), root.children)


@st.composite
def regression_terms(
    draw: st.DrawFn, max_terms: int = 6, max_size: int = 200
) -> tuple[np.ndarray, np.ndarray]:
    """A target y and 1–``max_terms`` columns of terms (rows of the returned matrix) that may
    be correlated, duplicated, constant or unrelated, as the effects of a diagnosis are."""
    n = draw(st.integers(8, max_size))
    k = draw(st.integers(1, max_terms))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    latent = rng.standard_normal((3, n))
    rows = np.empty((k, n))
    for j in range(k):
        form = draw(st.sampled_from(["mix", "copy", "constant", "noise"]))
        if form == "copy" and j > 0:
            rows[j] = draw(st.sampled_from([-1.0, 1.0])) * draw(st.floats(0.1, 3.0)) * rows[j - 1]
        elif form == "constant":
            rows[j] = 1.0
        elif form == "noise":
            rows[j] = rng.standard_normal(n)
        else:
            rows[j] = rng.standard_normal(3) @ latent + 0.3 * rng.standard_normal(n)
    y = rng.standard_normal(3) @ latent + draw(st.floats(-2.0, 2.0)) + rng.standard_normal(n)
    return y, rows


def time_series_of(kind: str, n: int, seed: int, parameter: float = 0.5) -> np.ndarray:
    """One series of ``kind`` (see :data:`SERIES_KINDS`); ``parameter`` in [0, 1] picks where
    in the kind's range its persistence, oscillation or trend lies.

    persistent: AR(1) with φ from 0.95 to 0.999 (near a unit root); random_walk: its φ = 1;
    oscillating: AR(2) with complex roots of modulus 0.8–0.97 at 0.2–1.5 rad per sample;
    trending: a linear trend of 1–10 innovation deviations over the record on AR(1) noise of
    φ = 0.7; heavy_tailed: Student-t innovations with 3 degrees of freedom, AR(1) with φ from 0
    to 0.9.
    """
    rng = np.random.default_rng(seed)
    burn = 500
    if kind == "heavy_tailed":
        shocks = rng.standard_t(3, size=n + burn)
    else:
        shocks = rng.standard_normal(n + burn)
    if kind == "persistent":
        ar = [0.95 + 0.049 * parameter]
    elif kind == "random_walk":
        return np.cumsum(shocks[:n])
    elif kind == "oscillating":
        modulus, angle = 0.8 + 0.17 * parameter, 0.2 + 1.3 * (1.0 - parameter)
        ar = [2.0 * modulus * np.cos(angle), -(modulus**2)]
    elif kind == "trending":
        ar = [0.7]
    elif kind == "heavy_tailed":
        ar = [0.9 * parameter]
    else:
        raise ValueError(f"unknown kind of series {kind!r}")
    series = sps.lfilter([1.0], np.concatenate(([1.0], -np.asarray(ar))), shocks)[burn:]
    if kind == "trending":
        series = series + (1.0 + 9.0 * parameter) * np.linspace(0.0, 1.0, n)
    return np.asarray(series, dtype=np.float64)


@st.composite
def time_series(draw: st.DrawFn, min_size: int = 200, max_size: int = 2000) -> np.ndarray:
    """A persistent, random-walk, oscillating, trending or heavy-tailed series (see
    :func:`time_series_of`), as residuals of vehicle models are."""
    kind = draw(st.sampled_from(SERIES_KINDS))
    n = draw(st.integers(min_size, max_size))
    return time_series_of(kind, n, draw(st.integers(0, 2**32 - 1)), draw(st.floats(0.0, 1.0)))
