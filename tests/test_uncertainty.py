"""Block-bootstrap intervals (pytest_hevval.core.uncertainty), checked by simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from scipy.signal import lfilter

from pytest_hevval.core.local import fixed_windows, group_lambdas, segment_sums
from pytest_hevval.core.uncertainty import (
    MIN_BLOCKS,
    block_length,
    bootstrap_draws,
    lag1_autocorrelation,
    percentile_interval,
    replicate_lambdas,
    replicate_sums,
)
from tests.strategies import signal_pairs


def _ar1(n: int, rho: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Stationary AR(1) with marginal standard deviation ``sigma``."""
    innovations = rng.normal(0.0, sigma * math.sqrt(1.0 - rho * rho), n)
    start = rng.normal(0.0, sigma)
    out, _ = lfilter([1.0], [1.0, -rho], innovations, zi=[rho * start])
    return np.asarray(out)


def _interval_of(reference: np.ndarray, simulated: np.ndarray, name: str) -> tuple[float, float]:
    n = reference.shape[0]
    b = block_length(n, lag1_autocorrelation(reference - simulated))
    starts, stops = fixed_windows(n, 1.0, float(b))
    blocks = segment_sums(reference, simulated, starts, stops)
    span = float(np.ptp(reference))
    whole = group_lambdas(segment_sums(reference, simulated, np.array([0]), np.array([n])), span)
    replicates = replicate_lambdas(blocks, bootstrap_draws(starts.shape[0], 400), span)
    found = percentile_interval(float(whole[name][0]), replicates[name])
    return found.low, found.high


def test_nominal_95_percent_intervals_cover_ar1_truth_90_to_99_percent_of_the_time() -> None:
    """λ3 and λ4 of a model whose error is AR(1) noise with ρ = 0.9 (strongly correlated)."""
    rng = np.random.default_rng(2024)
    n, rho, sigma, repeats = 20_000, 0.9, 1.0, 200
    reference = 50.0 * np.sin(np.arange(n) / 500.0)
    span = float(np.ptp(reference))
    truth = {
        "mae": 1.0 - sigma * math.sqrt(2.0 / math.pi) / span,  # E|e| of a normal variable
        "rms": 1.0 - sigma / span,
    }
    covered = dict.fromkeys(truth, 0)
    for _ in range(repeats):
        simulated = reference - _ar1(n, rho, sigma, rng)
        for name, value in truth.items():
            low, high = _interval_of(reference, simulated, name)
            covered[name] += low <= value <= high
    for name in truth:
        assert 0.90 <= covered[name] / repeats <= 0.99, (name, covered[name] / repeats)


def test_intervals_ignoring_the_correlation_would_not_cover() -> None:
    """The same simulation with one-sample blocks: the check above can fail."""
    rng = np.random.default_rng(5)
    n, rho, repeats = 20_000, 0.9, 60
    reference = 50.0 * np.sin(np.arange(n) / 500.0)
    truth = 1.0 - math.sqrt(2.0 / math.pi) / float(np.ptp(reference))
    covered = 0
    for _ in range(repeats):
        simulated = reference - _ar1(n, rho, 1.0, rng)
        starts, stops = fixed_windows(n, 1.0, 1.0)
        blocks = segment_sums(reference, simulated, starts, stops)
        replicates = replicate_lambdas(blocks, bootstrap_draws(n, 200), float(np.ptp(reference)))
        interval = percentile_interval(float(np.median(replicates["mae"])), replicates["mae"])
        covered += interval.low <= truth <= interval.high
    assert covered / repeats < 0.8


@pytest.mark.parametrize(
    ("n", "rho", "expected"),
    [
        (10_000, 0.0, 1),  # white residual: single samples
        # (√6·0.9/0.19)^(2/3) · 10000^(1/3) = 5.125 · 21.54 = 110.4 → 111
        (10_000, 0.9, 111),
        # (√6·0.99/0.0199)^(2/3) · 360000^(1/3) = 24.58 · 71.14 = 1748.6 → 1749
        (360_000, 0.99, 1_749),
        (50, 0.9, 5),  # 22 by the formula, clipped to 50 / MIN_BLOCKS
    ],
)
def test_block_length(n: int, rho: float, expected: int) -> None:
    assert block_length(n, rho) == expected
    assert n // block_length(n, rho) >= MIN_BLOCKS or block_length(n, rho) == 1


@given(signal_pairs(min_size=20))
@settings(max_examples=60, deadline=None)
def test_a_replicate_of_every_block_once_is_the_whole_record(
    pair: tuple[np.ndarray, np.ndarray],
) -> None:
    ref, sim = pair
    starts, stops = fixed_windows(ref.shape[0], 1.0, 4.0)
    blocks = segment_sums(ref, sim, starts, stops)
    identity = np.arange(starts.shape[0])[None, :]
    whole = segment_sums(ref, sim, np.array([0]), np.array([ref.shape[0]]))
    again = replicate_sums(blocks, identity)
    assert again.n[0] == whole.n[0]
    assert again.sign_matches[0] == whole.sign_matches[0]
    scale = float(np.sum((ref - sim) ** 2)) + 1.0
    assert again.error_m2[0] == pytest.approx(whole.error_m2[0], rel=1e-9, abs=1e-9 * scale)
    assert again.sq_error[0] == pytest.approx(whole.sq_error[0], rel=1e-9, abs=1e-9 * scale)


def test_draws_are_reproducible() -> None:
    assert np.array_equal(bootstrap_draws(50, 10), bootstrap_draws(50, 10))
    assert bootstrap_draws(50, 10).shape == (10, 50)


def test_interval_holds_its_value_and_prints_as_documented() -> None:
    interval = percentile_interval(0.9257, np.linspace(0.919, 0.9311, 1001))
    assert interval.low <= interval.value <= interval.high
    assert str(interval) == "0.9257 [0.9193, 0.9308]"
    assert percentile_interval(0.5, np.array([np.nan])).to_dict() == {
        "value": 0.5,
        "low": 0.5,
        "high": 0.5,
    }
