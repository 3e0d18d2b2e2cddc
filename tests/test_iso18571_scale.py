"""ISO/TS 18571 in any unit and on either kernel path: the same bits for a pair in units a
power of two apart, the same scores at 1e200 and 1e-300, and one warping path where equal-cost
paths tie."""

from __future__ import annotations

import math
from dataclasses import astuple

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_hevval.core import kernel
from pytest_hevval.core.standard import iso18571_rating
from pytest_hevval.core.standard.iso18571 import Iso18571Rating, _dtw_path
from pytest_hevval.errors import DegenerateSignalError
from tests.conftest import needs_kernel
from tests.strategies import quantised_pairs
from tests.test_standard_metrics import _crash_pulse, _iso_pairs

PATHS = ["numpy", pytest.param("numba", marks=needs_kernel)]


def _scores(r: Iso18571Rating) -> tuple[float, ...]:
    return (r.rating, r.corridor, r.phase, r.magnitude, r.slope, r.magnitude_error, r.slope_error)


def _held_at_2_to_the_minus_1000(curve: np.ndarray) -> np.ndarray:
    """``curve`` with the bits a value loses below 2^-1022 after ×2^-1000 dropped (values
    under 2^-22 lose some), so that the pair holds the same numbers in either unit."""
    return np.asarray(np.ldexp(np.ldexp(curve, -1000), 1000))


# --- units -----------------------------------------------------------------------------------


@pytest.mark.parametrize("exponent", [-1000, 600])
@pytest.mark.parametrize("case", sorted(_iso_pairs()))
def test_iso18571_is_the_same_bits_in_units_a_power_of_two_apart(
    case: str, exponent: int, kernel_path: str
) -> None:
    ref, sim = (_held_at_2_to_the_minus_1000(c) for c in _iso_pairs()[case])
    expected = astuple(iso18571_rating(ref, sim))
    assert astuple(iso18571_rating(np.ldexp(ref, exponent), np.ldexp(sim, exponent))) == expected


@pytest.mark.parametrize("unit", [1e200, 1e-300])
@pytest.mark.parametrize("case", sorted(_iso_pairs()))
def test_iso18571_scores_curves_at_1e200_and_1e_300_as_at_1(
    case: str, unit: float, kernel_path: str
) -> None:
    ref, sim = _iso_pairs()[case]
    expected = iso18571_rating(ref, sim)
    rating = iso18571_rating(ref * unit, sim * unit)
    assert (rating.shift, rating.band, rating.banded) == (
        expected.shift,
        expected.band,
        expected.banded,
    )
    # Each value rounds once on the way into the unit (by at most 1.1e-16 of itself).
    assert _scores(rating) == pytest.approx(_scores(expected), rel=1e-12, abs=1e-14)


def test_iso18571_rates_a_simulation_far_above_the_reference_without_overflow(
    kernel_path: str,
) -> None:
    # The reference's shape 2^700 times larger: in phase, and as far off as can be otherwise,
    # except where both curves are 0 (70 % of the samples), which the corridor holds.
    ref = _crash_pulse(800)
    rating = iso18571_rating(ref, np.ldexp(ref, 700))
    assert (rating.shift, rating.phase, rating.magnitude, rating.slope) == (0, 1.0, 0.0, 0.0)
    assert rating.corridor == np.mean(ref == 0.0)
    assert rating.rating == pytest.approx(0.4 * rating.corridor + 0.2)


def test_iso18571_refuses_magnitudes_beyond_the_float_range() -> None:
    # Scaled to the simulation's peak, the reference would be subnormal and lose its bits.
    with pytest.raises(DegenerateSignalError, match="differ by a factor beyond the float range"):
        iso18571_rating(_crash_pulse(800) * 1e-300, _crash_pulse(800) * 1e10)


# --- ties ------------------------------------------------------------------------------------


def _direct_path(x: np.ndarray, y: np.ndarray, band: int) -> list[tuple[int, int]]:
    """The warping path cell by cell as ISO/TS 18571 defines it: D[i, j] = (x_i − y_j)² plus
    the least of D up, left and diagonal, ties going up, then left, then diagonal."""
    n = len(x)
    d = [[math.inf] * n for _ in range(n)]
    step = [[0] * n for _ in range(n)]
    for i in range(n):
        for j in range(max(0, i - band), min(n, i + band + 1)):
            gap = float(x[i]) - float(y[j])
            if i == 0 and j == 0:
                d[0][0] = gap * gap
                continue
            up = d[i - 1][j] if i else math.inf
            left = d[i][j - 1] if j else math.inf
            diagonal = d[i - 1][j - 1] if i and j else math.inf
            best = min(up, left, diagonal)
            step[i][j] = 0 if up == best else 1 if left == best else 2
            d[i][j] = gap * gap + best
    i = j = n - 1
    path = [(i, j)]
    while i or j:
        move = step[i][j] if i and j else (1 if i == 0 else 0)
        i, j = (i - 1, j) if move == 0 else (i, j - 1) if move == 1 else (i - 1, j - 1)
        path.append((i, j))
    return path[::-1]


@pytest.mark.parametrize("path", PATHS)
def test_a_warping_tie_goes_left_before_diagonal_on_both_paths(path: str) -> None:
    # D[2, 1] = (x₂ − y₁)² + D[1, 1] = 0 + D[1, 1]: (2, 2) costs the same from the left and
    # diagonally, and the left step wins. A row's prefix sums once made the left 1 ulp dearer.
    x = np.array([2, 1, 0]) * 0.1
    y = np.array([3, 0, 0]) * 0.1
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(kernel.KERNEL_ENV, path)
        rows, cols = _dtw_path(x, y, 2)
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 0), (1, 1), (2, 1), (2, 2)]


@pytest.mark.parametrize("path", PATHS)
@given(pair=quantised_pairs(), band=st.integers(0, 60))
@settings(max_examples=150, deadline=None)
def test_the_warping_path_is_the_direct_recurrences_on_quantised_curves(
    path: str, pair: tuple[np.ndarray, np.ndarray], band: int
) -> None:
    x, y = pair
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(kernel.KERNEL_ENV, path)
        rows, cols = _dtw_path(x, y, band)
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == _direct_path(x, y, band)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("band", [0, 1, 37, 200])
def test_the_warping_path_is_the_direct_recurrences_across_blocks_of_diagonals(
    path: str, band: int
) -> None:
    # 700 samples: 1,399 diagonals, so the numpy path carries D over two block boundaries.
    rng = np.random.default_rng(band)
    x = np.repeat(rng.integers(-4, 5, 140), 5) * 0.1
    y = np.repeat(rng.integers(-4, 5, 100), 7) * 0.1
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(kernel.KERNEL_ENV, path)
        rows, cols = _dtw_path(x, y, band)
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == _direct_path(x, y, band)


def _outcome(path: str, ref: np.ndarray, sim: np.ndarray) -> tuple[object, ...]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(kernel.KERNEL_ENV, path)
        try:
            return astuple(iso18571_rating(ref, sim))
        except DegenerateSignalError as error:
            return (str(error),)


@needs_kernel
@given(pair=quantised_pairs(min_size=10, max_size=120))
@settings(max_examples=150, deadline=None)
def test_both_paths_rate_quantised_curves_alike(pair: tuple[np.ndarray, np.ndarray]) -> None:
    ref, sim = pair
    assume(np.ptp(ref) > 0)
    assert _outcome("numba", ref, sim) == _outcome("numpy", ref, sim)
