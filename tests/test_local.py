"""λ1–λ6 over time windows and operating regions (pytest_hevval.core.groups)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_hevval.core.characteristics import CHARACTERISTICS, signal_characteristics
from pytest_hevval.core.groups import (
    LOCAL_CHARACTERISTICS,
    MIN_GROUP_SAMPLES,
    PHASES,
    concentration,
    driving_phases,
    fixed_windows,
    group_lambdas,
    region_grid,
    region_sums,
    runs,
    segment_sums,
)
from pytest_hevval.errors import DegenerateSignalError
from pytest_hevval.results.local_tables import concentration_sentence
from tests.strategies import signal_pairs


def test_local_names_are_the_per_signal_characteristics_in_order() -> None:
    assert CHARACTERISTICS[:6] == LOCAL_CHARACTERISTICS


@given(signal_pairs(), st.sampled_from(["xcorr", "pearson"]))
@settings(max_examples=150, deadline=None)
def test_one_group_over_the_whole_record_is_the_global_result(
    pair: tuple[np.ndarray, np.ndarray], correlation: str
) -> None:
    ref, sim = pair
    if correlation == "pearson":
        # Pearson's variances come from Σx² − (Σx)²/n; for a signal constant to within
        # rounding that difference is rounding noise in both computations (the core and the
        # per-group sums add in different orders), so there is nothing to compare.
        assume(np.ptp(sim) > 1e-6 * (np.abs(sim).max() + 1))
    whole = signal_characteristics(ref, sim, dt=0.1, correlation=correlation)  # type: ignore[arg-type]
    n = ref.shape[0]
    sums = segment_sums(ref, sim, np.array([0]), np.array([n]))
    local = group_lambdas(sums, whole.reference_range, correlation)  # type: ignore[arg-type]
    # λ5 = 1 − (RMS − MAE)/R: the difference of two errors of the size of the RMS, so summed in
    # another order it agrees to 1e-9 of RMS/R, not of 1 (as ΔE itself is held to the RMS).
    anomaly_scale = max(1.0, whole.rms / whole.reference_range)
    for name, expected in zip(LOCAL_CHARACTERISTICS, whole.lambdas, strict=True):
        tolerance = 1e-9 * (anomaly_scale if name == "anomaly" else 1.0)
        assert local[name][0] == pytest.approx(expected, rel=1e-9, abs=tolerance), name


def test_a_bias_far_above_the_spread_leaves_the_groups_spread_exact() -> None:
    """Σ(e − ē)² per group, with a bias of 10^11 times the spread (a case hypothesis found):
    the same σ as exact rational arithmetic on the same errors, to rounding."""
    n = 47
    ref = np.zeros(n)
    ref[0] = 2.0**-14
    sim = np.full(n, 932068.2474171163)
    errors = [Fraction(float(x)) for x in ref - sim]
    mean = sum(errors) / n
    exact_m2 = float(sum((x - mean) ** 2 for x in errors))
    for starts, stops in (([0], [n]), ([0, 20], [20, n])):
        sums = segment_sums(ref, sim, np.array(starts), np.array(stops))
        if len(starts) == 1:
            assert sums.error_m2[0] == pytest.approx(exact_m2, rel=1e-12)
        else:
            for k, (a, b) in enumerate(zip(starts, stops, strict=True)):
                part = errors[a:b]
                part_mean = sum(part) / len(part)
                expected = float(sum((x - part_mean) ** 2 for x in part))
                assert sums.error_m2[k] == pytest.approx(expected, rel=1e-12, abs=1e-30)


@given(signal_pairs(min_size=10), st.integers(1, 40))
@settings(max_examples=100, deadline=None)
def test_windows_partition_the_record(pair: tuple[np.ndarray, np.ndarray], size: int) -> None:
    ref, sim = pair
    starts, stops = fixed_windows(ref.shape[0], 1.0, float(size))
    assert starts[0] == 0
    assert stops[-1] == ref.shape[0]
    assert np.array_equal(starts[1:], stops[:-1])
    sums = segment_sums(ref, sim, starts, stops)
    whole = segment_sums(ref, sim, np.array([0]), np.array([ref.shape[0]]))
    assert sums.n.sum() == ref.shape[0]
    assert sums.sign_matches.sum() == whole.sign_matches[0]
    scale = float(np.sum((ref - sim) ** 2)) + 1.0
    assert float(sums.sq_error.sum()) == pytest.approx(float(whole.sq_error[0]), abs=1e-9 * scale)
    values = group_lambdas(sums, float(np.ptp(ref)))
    for name in LOCAL_CHARACTERISTICS:
        judged = values[name][sums.n >= MIN_GROUP_SAMPLES]
        assert np.all((judged >= 0.0) & (judged <= 1.0)), name
        assert np.all(np.isnan(values[name][sums.n < MIN_GROUP_SAMPLES])), name


def _drive(n: int, dt: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    speed = 60.0 + 50.0 * np.sin(2 * np.pi * t / 300.0) + rng.normal(0.0, 0.5, n)
    return t, np.clip(speed, 0.0, None)


def test_an_error_in_one_60_s_stretch_is_found_there_and_only_there() -> None:
    dt = 0.1
    t, reference = _drive(36_000, dt)  # one hour at 10 Hz
    rng = np.random.default_rng(7)
    simulated = reference + rng.normal(0.0, 0.3, reference.shape[0])
    stretch = (t >= 1200.0) & (t < 1260.0)
    simulated[stretch] += 12.0  # the model misses something for one minute
    starts, stops = fixed_windows(t.shape[0], dt, 30.0)
    sums = segment_sums(reference, simulated, starts, stops)
    lambdas = group_lambdas(sums, float(np.ptp(reference)))
    failing = np.flatnonzero(lambdas["mae"] < 0.95)
    assert [(starts[k] * dt, stops[k] * dt) for k in failing] == [
        (1200.0, 1230.0),
        (1230.0, 1260.0),
    ]
    found = concentration(sums, starts, stops, dt)
    assert found.spans_s == ((1200.0, 1260.0),)
    assert found.windows == 2
    assert found.time_share == pytest.approx(60.0 / 3600.0)
    assert found.error_share > 0.9
    assert "1200–1260 s" in concentration_sentence(found)


def test_an_error_above_100_kmh_is_found_in_exactly_those_cells() -> None:
    dt = 0.1
    _, speed = _drive(36_000, dt, seed=3)
    rng = np.random.default_rng(11)
    torque = 80.0 * np.sin(np.arange(speed.shape[0]) * dt / 7.0) + rng.normal(
        0.0, 1.0, speed.shape[0]
    )
    simulated = torque + rng.normal(0.0, 0.5, speed.shape[0])
    simulated[speed > 100.0] *= 0.6  # the model is wrong only at high speed
    grid = region_grid([speed], [np.arange(0.0, 140.1, 20.0)])
    sums = region_sums(torque, simulated, grid)
    lambdas = group_lambdas(sums, float(np.ptp(torque)))
    judged = grid.counts.ravel() >= 100
    bad = np.flatnonzero(judged & (lambdas["mae"] < 0.9))
    lower_edges = grid.edges[0][:-1]
    high = np.flatnonzero(judged & (lower_edges >= 100.0))
    assert high.size  # the drive does reach 100 km/h
    assert bad.tolist() == high.tolist()
    assert np.all(lambdas["mae"][judged & (lower_edges < 100.0)] > 0.98)
    assert grid.unvisited() == [(6,)]  # 120–140 km/h is never driven


def test_two_variable_grid_counts_and_unvisited_cells() -> None:
    speed = np.array([5.0, 15.0, 15.0, 25.0, np.nan, 99.0])
    torque = np.array([-50.0, 10.0, 60.0, 60.0, 0.0, 0.0])
    grid = region_grid(
        [speed, torque], [np.array([0.0, 10.0, 20.0, 30.0]), np.array([-100.0, 0.0, 100.0])]
    )
    assert grid.shape == (3, 2)
    assert grid.counts.tolist() == [[1, 0], [0, 2], [0, 1]]
    assert grid.cell.tolist() == [0, 3, 3, 5, -1, -1]
    assert grid.unvisited() == [(0, 1), (1, 0), (2, 0)]


def test_the_last_bin_includes_its_upper_edge() -> None:
    grid = region_grid([np.array([0.0, 10.0, 20.0])], [np.array([0.0, 10.0, 20.0])])
    assert grid.counts.tolist() == [1, 2]


@pytest.mark.parametrize("edges", [[1.0], [2.0, 1.0], [0.0, 0.0, 1.0]])
def test_bad_bin_edges_are_refused(edges: list[float]) -> None:
    with pytest.raises(DegenerateSignalError, match="bin edges"):
        region_grid([np.zeros(3)], [np.array(edges)])


def test_runs_of_a_condition() -> None:
    mask = np.array([0, 1, 1, 0, 1, 0, 1, 1, 1], dtype=bool)
    starts, stops = runs(mask)
    assert list(zip(starts.tolist(), stops.tolist(), strict=True)) == [(1, 3), (4, 5), (6, 9)]
    starts, stops = runs(mask, min_samples=2)
    assert list(zip(starts.tolist(), stops.tolist(), strict=True)) == [(1, 3), (6, 9)]


def test_driving_phases_of_a_simple_trip() -> None:
    dt = 0.1
    # 20 s standing, 20 s accelerating to 72 km/h, 40 s cruising, 20 s braking, 20 s standing.
    profile = np.concatenate(
        [
            np.zeros(200),
            np.linspace(0.0, 72.0, 200),
            np.full(400, 72.0),
            np.linspace(72.0, 0.0, 200),
            np.zeros(200),
        ]
    )
    labels = driving_phases(profile, dt)
    names = [PHASES[k] for k in labels]
    assert names[100] == "stop"
    assert names[300] == "accelerate"
    assert names[600] == "cruise"
    assert names[900] == "brake"
    assert names[1100] == "stop"
    # Phases are manoeuvres: no phase shorter than two seconds.
    starts = np.flatnonzero(np.diff(labels)) + 1
    lengths = np.diff(np.concatenate(([0], starts, [labels.shape[0]])))
    assert lengths.min() * dt >= 2.0


def test_a_perfect_model_has_no_concentration() -> None:
    reference = np.sin(np.arange(1000) / 10.0)
    starts, stops = fixed_windows(1000, 0.1, 10.0)
    found = concentration(segment_sums(reference, reference, starts, stops), starts, stops, 0.1)
    assert found.windows == 0
    assert "spread out" in concentration_sentence(found)
