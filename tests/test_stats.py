"""The time-series statistics of the diagnosis (``core/stats.py``) on designs that break naive
linear algebra: a persistent residual, whose pre-whitening filter leaves a constant column of
10⁻⁵ beside regressors in other units."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval.core.residual import Candidate, diagnose_residual
from pytest_hevval.core.stats import (
    effective_samples,
    hac_fit,
    least_squares,
    politis_white,
    residualise,
)


def _random_walk_on_a_regressor(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = 10.0 * np.sin(np.arange(n) / 500.0) + rng.normal(size=n)
    return x + np.cumsum(rng.normal(size=n)), x


@pytest.mark.parametrize("seed", [8, 9])
def test_a_random_walk_keeps_its_intercept_uncertain_whatever_the_regressors_units(
    seed: int,
) -> None:
    """At n = 100 000 the AR fit of a random walk hits its cap, persistence 1 − 1/n: the
    whitened constant is 10⁻⁵ high. A cut-off on the singular values of X*ᵀX* dropped that
    direction and gave the intercept a standard error of 10⁻¹² (an offset "significant" with a
    point interval); with the regressor in other units it gave 300. Both must agree, and the
    mean of a random walk over 10⁵ steps is uncertain by hundreds of its steps."""
    y, x = _random_walk_on_a_regressor(seed, 100_000)
    ones = np.ones_like(x)
    as_is = hac_fit(y, np.column_stack([ones, x]), 1)
    in_milli = hac_fit(y, np.column_stack([ones, x * 1e3]), 1)
    assert float(np.sum(as_is.phi)) >= 1.0 - 1.5e-5  # the filter's cap: the case that broke
    se_as_is = np.sqrt(np.diag(as_is.cov))
    se_in_milli = np.sqrt(np.diag(in_milli.cov))
    assert se_as_is[0] > 100.0
    np.testing.assert_allclose(se_in_milli[0], se_as_is[0], rtol=1e-6)
    np.testing.assert_allclose(in_milli.beta[0], as_is.beta[0], rtol=1e-6)
    np.testing.assert_allclose(se_in_milli[1] * 1e3, se_as_is[1], rtol=1e-6)


def test_the_diagnosis_keeps_a_random_walks_offset_uncertain() -> None:
    """End to end: a random walk of 100 000 steps under a simulated signal switching between
    ±1000 and a white channel that drives the residual. The channel is selected, and the offset
    left beside it used to come out "significant" with a point interval (3 of 10 seeds); the
    mean of a random walk is uncertain by hundreds of its steps."""
    rng = np.random.default_rng(1)
    n = 100_000
    simulated = np.sign(rng.normal(size=n)) * 1000.0
    channel = rng.normal(size=n)
    reference = simulated + np.cumsum(rng.normal(size=n)) + 20.0 * channel
    found = diagnose_residual(
        reference,
        simulated,
        dt=0.1,
        max_samples=n,
        candidates=[Candidate("channel", "channel", channel)],
    )
    assert [f.name for f in found.candidates if f.selected and f.kind != "offset"] == ["channel"]
    (offset,) = [f for f in found.candidates if f.kind == "offset"]
    low, high = offset.interval
    assert high - low > 1000.0
    assert not offset.significant


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    exponents=st.lists(st.integers(-12, 12), min_size=1, max_size=4),
)
def test_least_squares_does_not_depend_on_column_units(seed: int, exponents: list[int]) -> None:
    """Scaling a column by 10^e scales its coefficient by 10^−e and changes no fitted value."""
    rng = np.random.default_rng(seed)
    n = 200
    x = np.column_stack([np.full(n, 1e-5), rng.normal(size=(n, len(exponents)))])
    y = rng.normal(size=n)
    units = np.concatenate(([1.0], 10.0 ** np.array(exponents, dtype=np.float64)))
    plain = least_squares(x, y)
    scaled = least_squares(x * units, y)
    assert plain.rank == scaled.rank == x.shape[1]
    np.testing.assert_allclose(scaled.coef * units, plain.coef, rtol=1e-8)
    np.testing.assert_allclose(
        np.diag(scaled.inverse) * units**2, np.diag(plain.inverse), rtol=1e-8
    )
    np.testing.assert_allclose(residualise(y, x * units), residualise(y, x), atol=1e-10)


def test_least_squares_agrees_with_lapack_on_ill_conditioned_and_singular_designs() -> None:
    """A design too ill-conditioned for its normal equations is solved through its SVD; an
    exactly repeated column is one direction, not two."""
    rng = np.random.default_rng(3)
    n = 500
    t = np.linspace(0.0, 1.0, n)
    ramp_and_bump = np.column_stack([np.ones(n), t, t + 1e-7 * rng.normal(size=n)])
    y = 2.0 + 3.0 * t + rng.normal(size=n)
    fit = least_squares(ramp_and_bump, y)
    expected, *_ = np.linalg.lstsq(ramp_and_bump, y, rcond=None)
    assert fit.rank == 3
    np.testing.assert_allclose(ramp_and_bump @ fit.coef, ramp_and_bump @ expected, atol=1e-9)
    repeated = np.column_stack([np.ones(n), t, t])
    fit = least_squares(repeated, y)
    assert fit.rank == 2
    np.testing.assert_allclose(fit.coef[1], fit.coef[2], rtol=1e-9)
    expected, *_ = np.linalg.lstsq(repeated, y, rcond=None)
    np.testing.assert_allclose(repeated @ fit.coef, repeated @ expected, atol=1e-9)
    both = residualise(np.column_stack([y, 2.0 * y]), repeated)
    np.testing.assert_allclose(both[:, 1], 2.0 * both[:, 0], atol=1e-10)
    np.testing.assert_allclose(both[:, 0], y - repeated @ fit.coef, atol=1e-10)


@pytest.mark.parametrize("n", [0, 1, 2, 3, 10])
def test_short_and_constant_series_have_blocks_of_one_and_all_their_samples(n: int) -> None:
    constant = np.full(n, 4.2)
    assert politis_white(constant).circular == 1.0
    assert politis_white(constant).stationary == 1.0
    if n:
        assert effective_samples(constant, 0) == float(n)
