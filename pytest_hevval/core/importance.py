"""Relative importance: how much of a fitted sum of squares each term explains.

Pure numpy. Terms that are correlated share what they explain; a share computed by dropping
or adding one term at a time then depends on the order or double-counts, and can even be
negative. The Shapley value of the explained sum of squares (Shapley 1953), known in
regression as the LMG decomposition (Lindeman, Merenda & Gold 1980; Grömping 2007), averages
each term's increase of the explained sum of squares over every order in which the terms can
enter:

    share_j = Σ_{S ⊆ T∖{j}} |S|! (k − |S| − 1)! / k! · [E(S ∪ {j}) − E(S)]

with E(S) the sum of squares of the target explained by the least-squares fit on the terms in
S. Because a least-squares fit can only explain more when a term is added, every increase is
non-negative, so every share is; the shares add up to E(T), whatever the order the terms are
listed in. Exact over all 2^k subsets, which is cheap for the handful of effects a diagnosis
keeps (k ≤ 12).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["MAX_TERMS", "explained_sums", "shapley_from_sums", "shapley_shares"]

FloatArray = npt.NDArray[np.float64]

#: The exact decomposition visits 2^k subsets.
MAX_TERMS = 12
_RCOND = 1e-10


def explained_sums(gram: FloatArray, cross: FloatArray) -> FloatArray:
    """E(S) for every subset S of the terms, indexed by the bit mask of S.

    ``gram`` is XᵀX and ``cross`` is Xᵀy for the k terms (columns of X) and the target y;
    E(S) = cross_Sᵀ (gram_SS)⁺ cross_S is the sum of squares of y explained by its
    least-squares fit on the columns in S (no intercept unless a column of ones is a term).
    Rounding can make a superset explain a hair less than a subset; E is made monotone, as it
    is exactly, so that no increase is negative.
    """
    gram = np.asarray(gram, dtype=np.float64)
    cross = np.asarray(cross, dtype=np.float64)
    k = cross.shape[0]
    if gram.shape != (k, k):
        raise ValueError(f"gram must be {k} × {k}, got {gram.shape}")
    if k > MAX_TERMS:
        raise ValueError(f"at most {MAX_TERMS} terms, got {k}")
    values = np.zeros(1 << k)
    for mask in range(1, 1 << k):
        idx = [j for j in range(k) if mask >> j & 1]
        sub = cross[idx]
        coef = np.linalg.pinv(gram[np.ix_(idx, idx)], rcond=_RCOND, hermitian=True) @ sub
        best = float(coef @ sub)
        # Monotone: at least what any subset one term smaller explains.
        for j in idx:
            best = max(best, float(values[mask & ~(1 << j)]))
        values[mask] = best
    return values


def shapley_shares(gram: FloatArray, cross: FloatArray, total: float) -> FloatArray:
    """Each term's Shapley share of the explained sum of squares, as a fraction of ``total``.

    The shares are non-negative and add up to E(all terms) / ``total``; with ``total`` the
    target's own sum of squares, that is the R² of the full fit (uncentred unless a column of
    ones is one of the terms). Returns zeros when ``total`` is not positive.
    """
    return shapley_from_sums(explained_sums(gram, cross), total)


def shapley_from_sums(values: FloatArray, total: float) -> FloatArray:
    """:func:`shapley_shares` from the explained sums of every subset, for a caller that needs
    those sums too (``values`` as :func:`explained_sums` returns them, 2^k of them)."""
    k = int(values.shape[0]).bit_length() - 1
    shares = np.zeros(k)
    if k == 0 or not total > 0.0:
        return shares
    weights = [math.factorial(s) * math.factorial(k - s - 1) / math.factorial(k) for s in range(k)]
    sizes = [bin(mask).count("1") for mask in range(1 << k)]
    for j in range(k):
        bit = 1 << j
        acc = 0.0
        for mask in range(1 << k):
            if mask & bit:
                continue
            acc += weights[sizes[mask]] * (values[mask | bit] - values[mask])
        shares[j] = acc
    return np.asarray(np.clip(shares / total, 0.0, None), dtype=np.float64)
