"""From the selected candidates to the effects one can act on: sized jointly, shared, judged
relevant or minor or standing in for another, each with the λ its fix predicts; and where in
time the residual concentrates."""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence

import numpy as np
import numpy.typing as npt

from ..groups import concentration, fixed_windows, group_lambdas, segment_sums
from ..importance import explained_sums
from ..stats import FloatArray, dot
from .candidates import _Scale, _Series
from .findings import Effect, Localisation
from .inference import _interval, _p_value, _scaled
from .shares import _interchangeable, _ordered_shares
from .sizing import _credited_centres, _fitted_terms, _least_squares_fit, _own_fix, _refitted, _Term
from .thresholds import GENERIC_KINDS, OFFSET_MATERIALITY, PREDICTED_CHARACTERISTICS


def _effects(
    ref: FloatArray,
    sim: FloatArray,
    scales: Sequence[_Scale],
    kept: list[_Series],
    selected: list[int],
    holm_levels: list[float],
    *,
    alpha: float,
    dt: float,
    start_s: float,
    min_share: float,
    window_s: float,
    scale: float,
    offset_name: str,
    in_units: set[str],
    leading: Collection[str] = (),
) -> tuple[tuple[Effect, ...], dict[str, float], dict[str, float], Localisation | None]:
    """The selected candidates and the intercept, fitted jointly, as effects one can act on.

    A candidate credited with the mean shift it carries enters uncentred (see
    :func:`_credited_centres`), so the intercept is the offset left over: a missing load with
    a nonzero mean is one effect, not a load and an offset. The joint model is fitted at every
    scale; each effect's coefficient, interval and test come from the scale where it is tested
    most sharply (Bonferroni over the scales), the one where it acts. Shares are the Shapley
    (LMG) decomposition of what all effects together explain of Σr² (:mod:`.importance`).
    """
    r = ref - sim
    n = r.shape[0]
    reference_range = float(np.ptp(ref))
    chosen = [kept[i] for i in selected]
    fine = scales[0]
    centres = _credited_centres(fine.r, chosen)
    fits, sizes, raw = _fitted_terms(
        scales, chosen, centres, holm_levels, alpha=alpha, dt=dt, scale=scale
    )
    # Gatekeeping, carried through to the sizes: the first family (the simulated signal's own
    # gain and lag, the loads in its dimension, the declared suspects) is judged on a model of
    # its own members, and the other channels only on what it leaves; a temperature that
    # follows the heater, entering later, then cannot dilute the heater's coefficient.
    family = [
        bool(leading) and (s.kind in GENERIC_KINDS or bool(set(leading) & {s.name, *s.members}))
        for s in chosen
    ]
    if any(family) and not all(family):
        members = [i for i, f in enumerate(family) if f]
        own = _refitted(members, scales, chosen, centres, holm_levels, alpha, dt, scale)
        for i, t in zip(members, own, strict=True):
            raw[i] = t
    joint, test = sizes[0], fits[0]
    se = np.sqrt(np.maximum(np.diag(joint.cov), 0.0))
    test_se = float(np.sqrt(max(float(test.cov[0, 0]), 0.0)))
    intercept, se0, df0 = float(joint.beta[0]), float(se[0]), int(joint.df[0])
    interval0 = _interval(intercept, se0, df0, alpha)
    p0 = _p_value(float(test.beta[0]), test_se, int(test.df[0]))
    offset_significant = (
        p0 <= alpha / 2.0
        and not (interval0[0] <= 0.0 <= interval0[1])
        and abs(intercept) > OFFSET_MATERIALITY * (reference_range or 1.0)
    )
    raw.append(
        _Term(
            name=offset_name,
            kind="offset",
            coefficient=intercept / scale,
            interval=_scaled(interval0, 1.0 / scale),
            p_value=p0,
            significant=offset_significant,
            term=np.full(n, intercept),
            mean_shift=intercept / scale,
            time_scale_s=fine.factor * dt,
            at_zero=intercept,
        )
    )
    where = _localise(ref, sim, dt, start_s, window_s)
    hot = _hot_mask(where, n, dt, start_s) if where is not None and where.windows else None
    # The Gram matrix of the effects' terms and the intercept, term by term: the terms are
    # full-rate series, and a stacked copy of them would double the memory they take. Each
    # term is its candidate scaled by its coefficient, which spans the same direction, so the
    # shares are those of the candidates.
    terms = [t.term for t in raw[: len(chosen)]]
    k = len(terms) + 1
    gram = np.empty((k, k))
    cross = np.empty(k)
    for a, term in enumerate(terms):
        for b in range(a, len(terms)):
            gram[a, b] = gram[b, a] = dot(term, terms[b])
        gram[a, -1] = gram[-1, a] = float(np.sum(term))
        cross[a] = dot(term, r)
    gram[-1, -1] = float(n)
    cross[-1] = float(np.sum(r))
    total = dot(r, r)
    together = explained_sums(gram, cross)
    # The intercept (last) belongs to the first family, with the generic terms.
    first_bits = [*family, True] if any(family) else [False] * k
    shares = [float(x) for x in _ordered_shares(together, first_bits, total)]
    swaps = _interchangeable(together, min_share * total)
    # Largest share first, an effect is a finding of its own unless a larger finding can stand
    # in for it: the explanation with the fewest terms is the one named. Where the record cannot
    # tell two measured effects apart, physics can: one measured in the scored signal's own
    # dimension (a load in kW for a power) is taken before one that is not (a temperature
    # that follows the load), as if it explained what the other does.
    in_dimension = [
        t.kind not in GENERIC_KINDS and bool(in_units & {t.name, *t.members}) for t in raw
    ]
    rank = list(shares)
    for i in range(len(raw)):
        if in_dimension[i]:
            for j in swaps[i]:
                if raw[j].kind not in GENERIC_KINDS and not in_dimension[j]:
                    rank[i] = max(rank[i], shares[j])
    findings: set[int] = set()
    fixes = [_own_fix(r, t) for t in raw]
    alone_shares = [fix.alone for fix in fixes]
    for i in sorted(range(len(raw)), key=lambda i: (-rank[i], not in_dimension[i], -shares[i])):
        t = raw[i]
        # Relevance asks what the effect does on its own, with its own fit: a joint
        # coefficient that a collinear term (a gain error against a load that follows the
        # driving) distorted says little of what adding the effect alone would remove.
        alone = alone_shares[i]
        if (
            t.significant
            and shares[i] >= min_share
            and alone >= min_share
            and not findings.intersection(swaps[i])
        ):
            findings.add(i)
    # A finding's size is fitted with the other findings and the intercept only: a minor term
    # that is nearly a combination of others (a gain against the road loads the model
    # computes) would otherwise distort it, and the fix a user applies is the finding alone.
    named = [i for i in sorted(findings) if i < len(chosen)]
    if named and len(named) < len(chosen):
        refitted = _refitted(named, scales, chosen, centres, holm_levels, alpha, dt, scale)
        for i, t in zip(named, refitted, strict=True):
            raw[i] = t._replace(significant=raw[i].significant)
    fixes = [_own_fix(r, t, refit=i in named) for i, t in enumerate(raw)]
    effects = [
        Effect(
            name=t.name,
            kind=t.kind,
            coefficient=t.coefficient,
            interval=t.interval,
            p_value=t.p_value,
            share=shares[i],
            offset_explained=t.mean_shift,
            significant=t.significant,
            relevant=i in findings,
            predicted=_lambdas(ref, sim + fixes[i].series, reference_range),
            hot_share=None if hot is None else _removed_share(r[hot], fixes[i].series[hot]),
            members=t.members,
            interchangeable=tuple(raw[j].name for j in swaps[i]),
            stands_in_for=()
            if i in findings or not t.significant
            else tuple(raw[j].name for j in swaps[i] if j in findings),
            time_scale_s=t.time_scale_s,
            alone_share=alone_shares[i],
            fix_coefficient=fixes[i].coefficient,
            fix_constant=fixes[i].constant / scale,
        )
        for i, t in enumerate(raw)
    ]
    # The joint coefficients share the residual between correlated terms; fixing only the
    # relevant ones is predicted with their own least-squares fit and a constant, so that a
    # minor term that compensated one of them in the joint model does not spoil the
    # prediction, and the model's constant is moved as the fix says.
    relevant_terms = [fixes[i].series for i in sorted(findings)]
    if relevant_terms:
        relevant_terms.append(np.ones(n))
    predicted = (
        _lambdas(ref, sim + _least_squares_fit(r, relevant_terms), reference_range)
        if relevant_terms
        else {}
    )
    # Findings are listed in the gatekeeping order they were tested in: the loads and the
    # spec's suspects, then the simulated signal's own gain, offset and lag, then any other
    # channel; by share within each. A generic term's joint share leans on the very terms the
    # model is built from (a gain against the road loads it computes), and describes the
    # simulation rather than naming what it lacks.
    first_names = set(leading)

    def tier(e: Effect) -> int:
        if not first_names:
            return 0
        if e.kind in GENERIC_KINDS:
            return 1
        return 0 if first_names & {e.name, *e.members} else 2

    effects.sort(key=lambda e: (not e.relevant, not e.significant, tier(e), -e.share))
    return tuple(effects), _lambdas(ref, sim, reference_range), predicted, where


def _lambdas(ref: FloatArray, sim: FloatArray, reference_range: float) -> dict[str, float]:
    """λ3 and λ4 of the whole pair, by the same sums the local characteristics use."""
    if not (reference_range > 0.0 and math.isfinite(reference_range)):
        return {}
    n = ref.shape[0]
    sums = segment_sums(ref, sim, np.array([0], dtype=np.int64), np.array([n], dtype=np.int64))
    values = group_lambdas(sums, reference_range)
    return {name: float(values[name][0]) for name in PREDICTED_CHARACTERISTICS}


def _removed_share(r: FloatArray, term: FloatArray) -> float:
    """Share of Σr² removed by subtracting ``term``: 1 − Σ(r − term)² / Σr²."""
    total = dot(r, r)
    if total <= 0.0:
        return 0.0
    left = r - term
    return 1.0 - dot(left, left) / total


def _hot_mask(where: Localisation, n: int, dt: float, start_s: float) -> npt.NDArray[np.bool_]:
    times = start_s + np.arange(n) * dt
    mask = np.zeros(n, dtype=bool)
    for a, b in where.spans_s:
        mask |= (times >= a - 0.5 * dt) & (times < b - 0.5 * dt)
    return mask


def _localise(
    ref: FloatArray, sim: FloatArray, dt: float, start_s: float, window_s: float
) -> Localisation | None:
    n = ref.shape[0]
    if window_s <= 0.0 or not math.isfinite(window_s):
        return None
    starts, stops = fixed_windows(n, dt, window_s)
    if starts.shape[0] < 2:
        return None
    found = concentration(segment_sums(ref, sim, starts, stops), starts, stops, dt, start_s)
    return Localisation(
        window_s=window_s,
        error_share=found.error_share,
        time_share=found.time_share,
        spans_s=found.spans_s,
        windows=found.windows,
    )
