"""The Shapley (LMG) decomposition of an explained sum of squares: a partition."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval.core.importance import (
    MAX_TERMS,
    explained_sums,
    shapley_from_sums,
    shapley_shares,
)

from .strategies import regression_terms


def _sums(y: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    return rows @ rows.T, rows @ y, float(y @ y)


def _explained(y: np.ndarray, rows: np.ndarray) -> float:
    """Σy² explained by the least-squares fit on ``rows``, straight from lstsq."""
    if rows.shape[0] == 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(rows.T, y, rcond=None)
    fitted = rows.T @ coef
    return float(y @ y - (y - fitted) @ (y - fitted))


@settings(max_examples=60, deadline=None)
@given(regression_terms())
def test_shares_partition_the_explained_fraction(case: tuple[np.ndarray, np.ndarray]) -> None:
    y, rows = case
    gram, cross, total = _sums(y, rows)
    shares = shapley_shares(gram, cross, total)
    assert np.all(shares >= 0.0)
    full = _explained(y, rows) / total
    assert float(np.sum(shares)) == pytest.approx(full, abs=1e-8)
    assert float(np.sum(shares)) <= 1.0 + 1e-9


@settings(max_examples=40, deadline=None)
@given(regression_terms(), st.randoms(use_true_random=False))
def test_shares_do_not_depend_on_the_order_terms_are_listed(
    case: tuple[np.ndarray, np.ndarray], shuffle: st.SearchStrategy
) -> None:
    y, rows = case
    order = list(range(rows.shape[0]))
    shuffle.shuffle(order)  # type: ignore[attr-defined]
    gram, cross, total = _sums(y, rows)
    shares = shapley_shares(gram, cross, total)
    g2, c2, _ = _sums(y, rows[order])
    assert shapley_shares(g2, c2, total) == pytest.approx(shares[order], abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(regression_terms(max_terms=4))
def test_shares_equal_the_average_over_every_order_of_entry(
    case: tuple[np.ndarray, np.ndarray],
) -> None:
    """The definition, computed the slow way: each term's gain averaged over all k! orders."""
    y, rows = case
    k = rows.shape[0]
    gram, cross, total = _sums(y, rows)
    expected = np.zeros(k)
    for order in itertools.permutations(range(k)):
        before = 0.0
        for pos, j in enumerate(order):
            after = _explained(y, rows[list(order[: pos + 1])])
            expected[j] += max(after - before, 0.0)
            before = max(after, before)
    expected /= math.factorial(k) * total
    assert shapley_shares(gram, cross, total) == pytest.approx(expected, abs=1e-7)


def test_a_duplicated_term_splits_its_share_and_an_unrelated_one_gets_nothing() -> None:
    rng = np.random.default_rng(3)
    a = rng.standard_normal(400)
    y = 2.0 * a
    unrelated = np.zeros(400)
    unrelated[::2] = 1.0
    unrelated -= unrelated.mean()
    # y is exactly 2a, so a term orthogonal to a explains nothing with a or without it.
    unrelated -= (unrelated @ a) / (a @ a) * a
    rows = np.stack([a, 3.0 * a, unrelated])
    shares = shapley_shares(*_sums(y, rows))
    assert shares == pytest.approx([0.5, 0.5, 0.0], abs=1e-12)


def test_explained_sums_are_monotone_and_bounded() -> None:
    rng = np.random.default_rng(5)
    rows = rng.standard_normal((5, 50))
    y = rng.standard_normal(50)
    gram, cross, total = _sums(y, rows)
    values = explained_sums(gram, cross)
    for mask in range(1 << 5):
        for j in range(5):
            assert values[mask | 1 << j] >= values[mask]
    assert values[-1] <= total


def test_too_many_terms_or_a_bad_gram_are_refused() -> None:
    k = MAX_TERMS + 1
    with pytest.raises(ValueError, match="at most"):
        explained_sums(np.eye(k), np.ones(k))
    with pytest.raises(ValueError, match="2 × 2"):
        explained_sums(np.eye(3), np.ones(2))
    assert shapley_shares(np.eye(2), np.ones(2), 0.0).tolist() == [0.0, 0.0]


def test_shares_in_the_gatekeeping_order_credit_the_first_family_first() -> None:
    """The first family shares what it explains together; the others share what they add to
    it; with every term in one family, the plain Shapley shares."""
    from pytest_hevval.core.residual.shares import _ordered_shares

    rng = np.random.default_rng(7)
    n = 400
    x = rng.standard_normal((n, 4))
    x[:, 3] = 0.9 * x[:, 0] + 0.1 * rng.standard_normal(n)  # a follower of term 0
    y = x[:, 0] + 0.5 * x[:, 1] + rng.standard_normal(n)
    gram, cross, total = x.T @ x, x.T @ y, float(y @ y)
    together = explained_sums(gram, cross)
    first = [True, True, False, False]
    shares = _ordered_shares(together, first, total)
    assert shares[:2].sum() == pytest.approx(together[0b0011] / total)
    assert shares[2:].sum() == pytest.approx((together[0b1111] - together[0b0011]) / total)
    assert np.all(shares >= 0.0)
    # The follower gets only what it adds to term 0, far less than its plain Shapley share.
    plain = shapley_from_sums(together, total)
    assert shares[3] < 0.5 * plain[3]
    np.testing.assert_allclose(_ordered_shares(together, [True] * 4, total), plain)
    np.testing.assert_allclose(_ordered_shares(together, [False] * 4, total), plain)
