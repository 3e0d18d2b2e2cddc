"""Block-bootstrap intervals (pytest_hevval.core.uncertainty), checked by simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from pytest_hevval.core.characteristics import signal_characteristics
from pytest_hevval.core.groups import SUM_COLUMNS, SumTable, group_lambdas, labelled_table
from pytest_hevval.core.uncertainty import (
    FINE_BLOCKS,
    MAX_BLOCKS,
    MIN_BLOCKS,
    NORMAL_QUANTILE,
    REPLICATES,
    BlockSums,
    block_length,
    block_sums,
    block_sums_many,
    coarsen,
    fine_block_size,
    fine_labels,
    lag1_autocorrelation,
    replicate_lambdas,
    replicate_sums,
    replicate_table,
    resample_counts,
    signal_intervals,
    stacked_intervals,
    stacked_replicates,
    standard_interval,
    sums_lambdas,
)
from tests.conftest import needs_kernel
from tests.strategies import signal_pairs


def _ar1(n: int, rho: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Stationary AR(1) with marginal standard deviation ``sigma``."""
    innovations = rng.normal(0.0, sigma * math.sqrt(1.0 - rho * rho), n)
    start = rng.normal(0.0, sigma)
    out, _ = lfilter([1.0], [1.0, -rho], innovations, zi=[rho * start])
    return np.asarray(out)


def _intervals(reference: np.ndarray, simulated: np.ndarray, *, per_block: int | None = None):
    blocks = block_sums(reference, simulated)
    span = float(np.ptp(reference))
    point = signal_characteristics(reference, simulated, dt=1.0, max_lag_s=0.0).values
    return signal_intervals(blocks, point, span, per_block=per_block)


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
        found = _intervals(reference, simulated)
        for name, value in truth.items():
            covered[name] += found[name].low <= value <= found[name].high
    for name in truth:
        assert 0.90 <= covered[name] / repeats <= 0.99, (name, covered[name] / repeats)


def test_intervals_ignoring_the_correlation_would_not_cover() -> None:
    """The same simulation with blocks of 5 samples (one fine block of a record of 5 · FINE_BLOCKS
    samples), far shorter than the correlation: the check above can fail."""
    rng = np.random.default_rng(5)
    n, rho, repeats = 5 * FINE_BLOCKS, 0.9, 60
    assert fine_block_size(n) == 5
    reference = 50.0 * np.sin(np.arange(n) / 500.0)
    truth = 1.0 - math.sqrt(2.0 / math.pi) / float(np.ptp(reference))
    covered = 0
    for _ in range(repeats):
        simulated = reference - _ar1(n, rho, 1.0, rng)
        interval = _intervals(reference, simulated, per_block=1)["mae"]
        covered += interval.low <= truth <= interval.high
    assert covered / repeats < 0.8


@pytest.mark.parametrize(
    ("n", "rho", "expected"),
    [
        (10_000, 0.0, 79),  # white residual: the rule's 1, raised to 10000 / MAX_BLOCKS
        # (√6·0.9/0.19)^(2/3) · 10000^(1/3) = 5.125 · 21.54 = 110.4 → 111
        (10_000, 0.9, 111),
        # (√6·0.99/0.0199)^(2/3) · 360000^(1/3) = 24.58 · 71.14 = 1748.6, below 360000 / 128
        (360_000, 0.99, 2_813),
        (10**8, 0.99, 781_250),  # 24.58 · 464.2 = 11,410, raised to 10^8 / 128
        (50, 0.9, 5),  # 22 by the formula, clipped to 50 / MIN_BLOCKS
    ],
)
def test_block_length(n: int, rho: float, expected: int) -> None:
    assert block_length(n, rho) == expected
    assert n // block_length(n, rho) >= MIN_BLOCKS or block_length(n, rho) == 1
    assert math.ceil(n / block_length(n, rho)) <= MAX_BLOCKS


def test_blocks_are_whole_fine_blocks_at_least_as_long_as_the_rule_asks() -> None:
    n = 360_000
    fine = fine_block_size(n)
    assert fine == math.ceil(n / FINE_BLOCKS) == 352
    rows = math.ceil(n / fine)
    blocks = BlockSums(
        labelled_table(np.zeros(n), np.zeros(n), np.zeros(n, np.int64), rows), fine, n, 0.99
    )
    # 2,813 samples (360000 / MAX_BLOCKS) → 8 fine blocks of 352 = 2,816 samples
    assert blocks.per_block == 8
    assert blocks.block_samples == 2_816


@given(signal_pairs(min_size=20))
@settings(max_examples=60, deadline=None)
def test_a_replicate_of_every_block_once_is_the_whole_record(
    pair: tuple[np.ndarray, np.ndarray],
) -> None:
    ref, sim = pair
    n = ref.shape[0]
    table = coarsen(block_sums(ref, sim).table, 4)
    once = np.ones((1, table.values.shape[0]))
    again = replicate_table(table, once).sums()
    whole = labelled_table(ref, sim, np.zeros(n, np.int64), 1).sums()
    assert again.n[0] == whole.n[0] == n
    assert again.sign_matches[0] == whole.sign_matches[0]
    scale = float(np.sum((ref - sim) ** 2)) + 1.0
    assert again.error_m2[0] == pytest.approx(whole.error_m2[0], rel=1e-9, abs=1e-9 * scale)
    assert again.sq_error[0] == pytest.approx(whole.sq_error[0], rel=1e-9, abs=1e-9 * scale)
    span = float(np.ptp(ref)) or 1.0
    for name, values in group_lambdas(again, span).items():
        expected = group_lambdas(whole, span)[name][0]
        assert values[0] == pytest.approx(expected, rel=1e-9, abs=1e-12, nan_ok=True)


def test_draws_are_reproducible_and_draw_every_replicate_full() -> None:
    counts = resample_counts(50, 10)
    assert np.array_equal(counts, resample_counts(50, 10, seed=20_140_601))
    assert counts.shape == (10, 50)
    assert np.all(counts.sum(axis=1) == 50)
    assert not counts.flags.writeable
    assert not np.array_equal(counts, resample_counts(50, 10, seed=1))


def test_interval_is_the_value_plus_minus_z_standard_errors() -> None:
    assert pytest.approx(1.959963984540054, rel=1e-15) == NORMAL_QUANTILE
    # 48 replicates at the value and one 0.01 either side: s = √(2·0.01² / 49) = 0.0020203,
    # z·s = 0.0039597, well inside the replicates' span, so nothing is cut.
    replicates = np.r_[np.full(48, 0.93), 0.92, 0.94]
    interval = standard_interval(0.93, replicates)
    spread = 1.959963984540054 * math.sqrt(2 * 0.01**2 / 49)
    assert interval.low == pytest.approx(0.93 - spread, rel=1e-12)
    assert interval.high == pytest.approx(0.93 + spread, rel=1e-12)
    # Four replicates 0.90–0.95: 0.93 ± z·0.0208 = [0.889, 0.971], cut to their span.
    assert standard_interval(0.93, np.array([0.90, 0.92, 0.93, 0.95])).to_dict() == {
        "value": 0.93,
        "low": 0.90,
        "high": 0.95,
    }


def test_interval_keeps_the_bounds_of_its_characteristic_and_holds_its_value() -> None:
    # λ near 1: the replicates pile up at 1 and the interval stops there.
    near_one = standard_interval(0.999, np.clip(np.linspace(0.98, 1.02, 401), 0.0, 1.0))
    assert near_one.low < 0.999
    assert near_one.high == 1.0
    # A value outside its replicates' span (λ7 clipped at 1) is still inside its interval.
    outside = standard_interval(1.0, np.linspace(0.90, 0.95, 11))
    assert outside.low <= outside.value == outside.high == 1.0


def test_interval_prints_as_documented_and_is_the_point_without_replicates() -> None:
    replicates = 0.9257 + np.r_[-0.01, np.zeros(8), 0.01]  # s = 0.0047140, z·s = 0.0092393
    interval = standard_interval(0.9257, replicates)
    assert str(interval) == "0.9257 [0.9165, 0.9349]"
    assert interval.bounds == "[0.9165, 0.9349]"
    for replicates in (np.array([np.nan, 0.4]), np.array([]), np.array([0.3])):
        assert standard_interval(0.5, replicates).to_dict() == {
            "value": 0.5,
            "low": 0.5,
            "high": 0.5,
        }
    assert math.isnan(standard_interval(float("nan"), np.array([0.1, 0.2])).low)


# -- the batched path the engine takes -----------------------------------------------------


@given(st.lists(signal_pairs(min_size=3, max_size=40), min_size=1, max_size=4))
@settings(max_examples=60, deadline=None)
def test_stacked_block_sums_are_the_per_signal_pass_bit_for_bit(
    pairs: list[tuple[np.ndarray, np.ndarray]],
) -> None:
    n = min(ref.shape[0] for ref, _ in pairs)
    pairs = [(ref[:n], sim[:n]) for ref, sim in pairs]
    for (ref, sim), blocks in zip(pairs, block_sums_many(pairs, compiled=False), strict=True):
        fine = fine_block_size(n)
        table = labelled_table(ref, sim, fine_labels(n, fine), math.ceil(n / fine), compiled=False)
        assert blocks.fine == fine
        assert blocks.table.shift == table.shift
        np.testing.assert_array_equal(blocks.table.values, table.values)
        # ρ is taken of the rescaled residual, where squares of tiny values do not underflow.
        assert blocks.rho == lag1_autocorrelation(ref * blocks.scale - sim * blocks.scale)


def test_stacked_block_sums_cover_whole_and_partial_fine_blocks() -> None:
    rng = np.random.default_rng(3)
    for n in (4_096, 4_097, 10_001, 12_288):
        pairs = [(rng.normal(size=n), rng.normal(size=n)) for _ in range(3)]
        for (ref, sim), blocks in zip(pairs, block_sums_many(pairs, compiled=False), strict=True):
            fine = fine_block_size(n)
            table = labelled_table(
                ref, sim, fine_labels(n, fine), math.ceil(n / fine), compiled=False
            )
            np.testing.assert_array_equal(blocks.table.values, table.values)
            assert blocks.table.values[:, 0].sum() == n


def test_huge_values_are_summed_at_a_power_of_two_scale_signal_by_signal() -> None:
    rng = np.random.default_rng(4)
    small = (rng.normal(size=500), rng.normal(size=500))
    huge = (1e300 * rng.normal(size=500), 1e300 * rng.normal(size=500))
    one, other = block_sums_many([small, huge], compiled=False)
    assert one.scale == 1.0
    assert other.scale != 1.0
    assert math.log2(other.scale).is_integer()
    assert np.all(np.isfinite(other.table.values))
    assert np.array_equal(one.table.values, block_sums(*small, compiled=False).table.values)


def _agrees_to_rounding(
    ref: np.ndarray, sim: np.ndarray, fast: BlockSums, plain: BlockSums
) -> None:
    """Every column of the compiled fine-block sums is the numpy pass's to rounding: each row
    within a few ulps of the magnitude of its terms times its length (the compiled loop adds
    a block's samples in another order and fuses products into sums); the counts exactly.
    The shifted columns are compared about the compiled pass's own shift."""
    n = ref.shape[0]
    labels = fine_labels(n, fast.fine)
    rows = math.ceil(n / fast.fine)
    r, s = ref * fast.scale, sim * fast.scale
    e = r - s
    d = e - fast.table.shift
    terms = (d, d * d, np.abs(e), r, s, r * r, s * s, r * s)
    sums = [np.bincount(labels, weights=t, minlength=rows) for t in terms]
    magnitude = [np.bincount(labels, weights=np.abs(t), minlength=rows) for t in terms]
    length = np.bincount(labels, minlength=rows).astype(np.float64)
    for c, (expected, size) in enumerate(zip(sums, magnitude, strict=True), start=1):
        bound = 4.0 * np.finfo(np.float64).eps * (length + 2.0) * size
        assert np.all(np.abs(fast.table.values[:, c] - expected) <= bound), SUM_COLUMNS[c]
    np.testing.assert_array_equal(fast.table.values[:, 0], plain.table.values[:, 0])
    np.testing.assert_array_equal(fast.table.values[:, 9], plain.table.values[:, 9])


@needs_kernel
@given(st.lists(signal_pairs(max_size=3000), min_size=1, max_size=4))
@settings(max_examples=60, deadline=None)
def test_compiled_block_sums_are_the_numpy_pass(pairs: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """The compiled fine-block pass: the same scale, fine blocks and counts; the sums to
    rounding (reassociated, as the main pass's and the windows' are); the shift (a mean of up
    to 1,024 errors, added in another order) to rounding; ρ to rounding."""
    n = min(ref.shape[0] for ref, _ in pairs)
    pairs = [(ref[:n], sim[:n]) for ref, sim in pairs]
    plain = block_sums_many(pairs, compiled=False)
    fast = block_sums_many(pairs, compiled=True)
    for (ref, sim), a, b in zip(pairs, plain, fast, strict=True):
        assert (b.fine, b.n, b.scale) == (a.fine, a.n, a.scale)
        errors = np.abs(ref * a.scale - sim * a.scale)[: min(n, 1024)]
        assert abs(b.table.shift - a.table.shift) <= 1e-13 * float(errors.max(initial=0.0))
        _agrees_to_rounding(ref, sim, b, a)
        assert b.rho == pytest.approx(a.rho, abs=1e-9)


@needs_kernel
def test_compiled_rho_keeps_a_shift_far_below_the_values_ulp() -> None:
    """The errors 1e-39, 0, 0 from values of 1: the shift (their head's mean, 3.4e-40) must
    not vanish into r − (s + shift) in the compiled lag products (a case hypothesis found)."""
    ref = np.array([1.01755607e-39, 1.0, 0.0])
    sim = np.array([0.0, 1.0, 0.0])
    (plain,) = block_sums_many([(ref, sim)], compiled=False)
    (fast,) = block_sums_many([(ref, sim)], compiled=True)
    assert plain.rho == pytest.approx(-1.0 / 6.0)
    assert fast.rho == pytest.approx(plain.rho, abs=1e-12)


@needs_kernel
def test_compiled_block_sums_of_long_records_and_extreme_scales() -> None:
    rng = np.random.default_rng(8)
    for n in (1_023, 1_025, 6_000, 70_001):
        drift = np.cumsum(rng.normal(size=n))
        pairs = [
            (rng.normal(size=n), rng.normal(size=n)),
            (1e300 * rng.normal(size=n), 1e300 * rng.normal(size=n)),
            (1e-300 * rng.normal(size=n), 1e-300 * rng.normal(size=n)),
            (drift + 1e6, drift + rng.normal(size=n)),
            # A bias that dwarfs the spread (ρ from a second, centred loop), an error that
            # drifts away from its first samples' mean, and peaks just inside the unscaled
            # range that only the peak itself can clear (2^397 and 2^-397).
            (drift, drift - 1e3 - 1e-3 * rng.normal(size=n)),
            (drift, drift - np.linspace(0.0, 50.0, n) - rng.normal(size=n)),
            (2.0**397 * rng.normal(size=n), 2.0**397 * rng.normal(size=n)),
            (2.0**-397 * rng.normal(size=n), 2.0**-397 * rng.normal(size=n)),
        ]
        plain = block_sums_many(pairs, compiled=False)
        fast = block_sums_many(pairs, compiled=True)
        for (ref, sim), a, b in zip(pairs, plain, fast, strict=True):
            assert (b.fine, b.scale) == (a.fine, a.scale)
            assert np.all(np.isfinite(b.table.values))
            _agrees_to_rounding(ref, sim, b, a)
            assert b.rho == pytest.approx(a.rho, abs=1e-9)
            assert b.per_block == a.per_block


@pytest.mark.parametrize("compiled", [False, pytest.param(True, marks=needs_kernel)])
def test_a_constant_error_has_no_autocorrelation(compiled: bool) -> None:
    """The mean of a constant 0.1 is not exactly 0.1; centring on it must not leave a constant
    remainder whose ρ is near 1."""
    ref = np.full(5_000, 0.1)
    (blocks,) = block_sums_many([(ref, np.zeros_like(ref))], compiled=compiled)
    assert blocks.rho == 0.0
    assert lag1_autocorrelation(ref) == 0.0


@given(signal_pairs(min_size=30), st.sampled_from(["xcorr", "pearson"]))
@settings(max_examples=60, deadline=None)
def test_sums_lambdas_are_group_lambdas(pair: tuple[np.ndarray, np.ndarray], kind: str) -> None:
    ref, sim = pair
    table = coarsen(block_sums(ref, sim).table, 3)
    span = float(np.ptp(ref))
    columns = {name: table.values[:, c] for c, name in enumerate(SUM_COLUMNS)}
    found = sums_lambdas(columns, table.shift, span, kind)
    expected = group_lambdas(table.sums(), span, kind)  # type: ignore[arg-type]
    assert list(found) == list(expected)
    for name in expected:
        np.testing.assert_allclose(found[name], expected[name], rtol=0, atol=1e-12)


@given(
    st.lists(signal_pairs(min_size=40, max_size=120), min_size=1, max_size=5),
    st.lists(st.integers(1, 6), min_size=5, max_size=5),
    st.sampled_from(["xcorr", "pearson"]),
)
@settings(max_examples=40, deadline=None)
def test_batched_lambdas_equal_per_signal_lambdas(
    pairs: list[tuple[np.ndarray, np.ndarray]], per_blocks: list[int], kind: str
) -> None:
    n = min(ref.shape[0] for ref, _ in pairs)
    pairs = [(ref[:n], sim[:n]) for ref, sim in pairs]
    blocks = block_sums_many(pairs, compiled=False)
    spans = [float(np.ptp(ref)) or 1.0 for ref, _ in pairs]
    # Every signal twice: at a length shared by all, and at its own.
    tables = [b.table for b in blocks] * 2
    lengths = [per_blocks[0]] * len(blocks) + per_blocks[: len(blocks)]
    ranges = [s * b.scale for s, b in zip(spans, blocks, strict=True)] * 2
    found = stacked_replicates(tables, lengths, ranges, kind)
    for column, (table, length, span) in enumerate(zip(tables, lengths, ranges, strict=True)):
        coarse = coarsen(table, length)
        counts = resample_counts(coarse.values.shape[0])
        one = replicate_lambdas(coarse, counts, span, kind)
        # λ are computed from differences of sums (Σe² − (Σe)²/n, Σxy − ΣxΣy/n, RMS − MAE), so
        # two summation orders agree only to ε times the condition number of that difference:
        # huge for a replicate drawn from nearly constant blocks (Pearson's λ1 may even jump
        # between 0 and 1 there). Every λ must agree to 1e-12 plus its rounding bound.
        allowed = _rounding_bounds(replicate_table(coarse, counts), span, kind)
        for name, values in one.items():
            batched = found[name][:, column]
            same = np.abs(batched - values) <= 1e-12 + allowed[name]
            same |= np.isnan(values) & np.isnan(batched)
            assert same.all(), (name, batched[~same], values[~same])


#: A rounding error bound's multiple of ε: generous for sums of a few hundred terms.
ROUNDING = 2.0**-40


def _rounding_bounds(table: SumTable, span: float, kind: str) -> dict[str, np.ndarray]:
    """How far each replicate's λ may move when its sums are added in another order."""
    sums = table.sums()
    n = np.maximum(sums.n, 1).astype(float)
    shifted_sq = table.values[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        # λ6: σ² = (Σd² − (Σd)²/n) / (n − 1) moves by ε·Σd²/(n − 1); σ by that over 2σ, and
        # never by more than its square root.
        variance_error = ROUNDING * shifted_sq / np.maximum(n - 1.0, 1.0)
        sigma = np.sqrt(sums.error_m2 / np.maximum(n - 1.0, 1.0))
        sigma_error = np.minimum(np.sqrt(variance_error), variance_error / (2.0 * sigma))
        # λ4: Σe² = Σd² + 2kΣd + nk² (d = e − k) moves by ε times its terms; RMS by that over
        # 2·RMS·n, never by more than its square root. λ5 adds MAE's ε·MAE.
        shifted_sum, shift = table.values[:, 1], table.shift
        square_error = (
            ROUNDING * (shifted_sq + np.abs(2.0 * shift * shifted_sum) + n * shift**2) / n
        )
        rms = np.sqrt(sums.sq_error / n)
        rms_error = np.minimum(np.sqrt(square_error), square_error / (2.0 * rms))
        mae_error = ROUNDING * sums.abs_error / n
        lag = np.zeros_like(n)
        if kind == "pearson":
            for a, b, product in (
                (sums.ref_sum, sums.sim_sum, sums.cross),
                (sums.ref_sum, sums.ref_sum, sums.ref_sq),
                (sums.sim_sum, sums.sim_sum, sums.sim_sq),
            ):
                lag += (np.abs(product) + np.abs(a * b / n)) / np.abs(product - a * b / n)
            lag = ROUNDING * np.nan_to_num(lag, nan=np.inf)
    return {
        "lag_correlation": lag,
        "derivative_match": np.zeros_like(n),
        "mae": mae_error / span,
        "rms": np.nan_to_num(rms_error, nan=np.inf) / span,
        "anomaly": np.nan_to_num(rms_error + mae_error, nan=np.inf) / span,
        "error_std": np.nan_to_num(sigma_error, nan=np.inf) / span,
    }


@pytest.mark.parametrize(
    ("replicates", "blocks", "width"),
    [(1000, 125, 10), (1000, 40, 160), (7, 3, 2), (1000, 128, 2100)],
)
def test_replicate_sums_cut_into_small_products_equal_one_product(
    replicates: int, blocks: int, width: int
) -> None:
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 4, (replicates, blocks)).astype(np.float64)
    rows = rng.normal(size=(blocks, width))
    np.testing.assert_allclose(replicate_sums(counts, rows), counts @ rows, rtol=1e-13, atol=1e-12)


def test_stacked_intervals_are_standard_intervals() -> None:
    rng = np.random.default_rng(6)
    table = rng.normal(size=(5, REPLICATES))
    table[2, 10] = np.nan  # a row with a non-finite replicate is handled on its own
    values = [0.1, 5.0, 0.0, float("nan"), -0.2]
    found = stacked_intervals(values, table)
    for value, row, interval in zip(values, table, found, strict=True):
        expected = standard_interval(value, row)
        assert interval.value == expected.value or math.isnan(value)
        assert interval.low == pytest.approx(expected.low, abs=1e-15, nan_ok=True)
        assert interval.high == pytest.approx(expected.high, abs=1e-15, nan_ok=True)
