"""How the residual's explained sum of squares is shared between effects: Shapley shares in the
gatekeeping order (Owen's value with two unions, :mod:`..importance` for the plain ones), and
which effects can stand in for each other on a record."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..importance import shapley_from_sums
from ..stats import FloatArray
from .thresholds import INTERCHANGEABLE_OVERLAP


def _ordered_shares(together: FloatArray, first: Sequence[bool], total: float) -> FloatArray:
    """Shapley shares in the gatekeeping order: the first family's terms share what they
    explain together, and the others share what they add to it (each family a game of its own,
    as in Owen's value with two unions in that order). With no first family, or all terms in
    it, the plain Shapley shares."""
    k = len(first)
    inside = [i for i in range(k) if first[i]]
    outside = [i for i in range(k) if not first[i]]
    if not inside or not outside:
        return shapley_from_sums(together, total)

    def game(players: Sequence[int], base: int) -> FloatArray:
        values = np.empty(1 << len(players))
        for sub in range(1 << len(players)):
            mask = base
            for b, i in enumerate(players):
                if sub >> b & 1:
                    mask |= 1 << i
            values[sub] = float(together[mask]) - float(together[base])
        return shapley_from_sums(values, total)

    first_mask = sum(1 << i for i in inside)
    shares = np.zeros(k)
    shares[inside] = game(inside, 0)
    shares[outside] = game(outside, first_mask)
    return shares


def _interchangeable(together: FloatArray, floor: float) -> list[list[int]]:
    """For each term, the other terms that can stand in for it on this record: each explains
    at least ``floor`` alone, and what they explain in common is at least
    :data:`INTERCHANGEABLE_OVERLAP` of what the smaller explains alone. ``together`` holds
    what every subset of the terms explains (:func:`.importance.explained_sums`)."""
    k = int(together.shape[0]).bit_length() - 1
    found: list[list[int]] = [[] for _ in range(k)]
    for a in range(k):
        for b in range(a + 1, k):
            ea, eb = float(together[1 << a]), float(together[1 << b])
            common = ea + eb - float(together[(1 << a) | (1 << b)])
            if min(ea, eb) >= floor and common >= INTERCHANGEABLE_OVERLAP * min(ea, eb):
                found[a].append(b)
                found[b].append(a)
    return found
