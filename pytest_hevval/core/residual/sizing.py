"""How large each selected effect is: the selected candidates and an intercept fitted jointly at
every scale, tested on the filtered regression and sized by least squares with the covariance
of the residual's AR model on the coarsest scale where the effect passes; the mean shift each
term is credited with, and each effect's own fit as the fix a user applies."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..stats import RCOND, FloatArray, HacFit, ar_model_fit, block_means, dot, hac_fit
from .candidates import _Scale, _Series
from .inference import _excludes_zero, _interval, _p_value, _scaled


def _credited_centres(r_g: FloatArray, chosen: Sequence[_Series]) -> list[float]:
    """Where each selected term is zero: 0 (it carries the mean it implies) or its mean.

    In the order the terms entered, a channel, expression or derivative is credited with the
    mean shift coefficient × mean(channel) when that brings the offset left over closer to
    zero: a missing heater load explains the mean shift it causes. A term whose mean would
    only have to be cancelled by a larger opposite offset (the throttle position, whose zero
    is far from its working range) keeps its mean out, as the lag always does. The gain always
    carries its mean: the offset is then the one at simulated = 0, as in the headline fit.
    """
    columns = [(s.grid - s.mean) / s.std for s in chosen]
    design = np.column_stack([np.ones_like(r_g), *columns])
    beta, *_ = np.linalg.lstsq(design, r_g, rcond=RCOND)
    left = float(np.mean(r_g))
    centres: list[float] = []
    for pos, s in enumerate(chosen, start=1):
        carried = float(beta[pos]) / s.std * s.mean
        # The gain term is the simulated signal itself: as in the headline fit, the offset is
        # the one at simulated = 0, so a pure gain error shows no offset.
        if s.kind == "gain" or (s.kind != "lag" and abs(left - carried) < abs(left)):
            centres.append(0.0)
            left -= carried
        else:
            centres.append(s.mean)
    return centres


class _Term(NamedTuple):
    """One selected candidate, or the intercept, as fitted jointly: what becomes an Effect."""

    name: str
    kind: str
    coefficient: float
    interval: tuple[float, float]
    p_value: float
    significant: bool
    # The effect as a full-rate series in the rescaled signal's units.
    term: FloatArray
    mean_shift: float
    time_scale_s: float
    members: tuple[str, ...] = ()
    # The term's value where its candidate is zero (rescaled units): -coefficient × centre.
    at_zero: float = 0.0


def _fitted_terms(
    scales: Sequence[_Scale],
    chosen: Sequence[_Series],
    centres: Sequence[float],
    holm_levels: Sequence[float],
    *,
    alpha: float,
    dt: float,
    scale: float,
) -> tuple[list[HacFit], list[HacFit], list[_Term]]:
    """The chosen candidates and an intercept fitted jointly at every scale: tested on the
    filtered regression (:func:`.stats.hac_fit`), sized by least squares with the covariance
    of its residual's AR model (:func:`.stats.ar_model_fit`); each term's test, coefficient and
    interval from the scale where it is tested most sharply (its p-value times the number of
    scales). Returns (the tests' fits, the sizes' fits, the terms)."""
    fine = scales[0]
    fits: list[HacFit] = []
    sizes: list[HacFit] = []
    for sc in scales:
        columns = [
            (s.grid if sc is fine else block_means(s.full, sc.factor)) - c
            for s, c in zip(chosen, centres, strict=True)
        ]
        design = np.column_stack(
            [np.ones_like(sc.r), *(col / s.std for col, s in zip(columns, chosen, strict=True))]
        )
        fits.append(hac_fit(sc.r, design, sc.order))
        sizes.append(ar_model_fit(sc.r, design, sc.order))
    errors = [np.sqrt(np.maximum(np.diag(fit.cov), 0.0)) for fit in fits]
    size_errors = [np.sqrt(np.maximum(np.diag(fit.cov), 0.0)) for fit in sizes]
    terms: list[_Term] = []
    for pos, (s, centre) in enumerate(zip(chosen, centres, strict=True), start=1):
        tests = [
            _p_value(float(fit.beta[pos]), float(se[pos]), int(fit.df[pos]))
            for fit, se in zip(fits, errors, strict=True)
        ]
        # Sized on the coarsest scale where the effect is still shown (its test passes and
        # its interval excludes zero): block means average out what a measured channel's own
        # noise and the timing jitter between model and measurement add at the fine scale,
        # which would dilute the coefficient toward zero. An effect is significant only where
        # both say so, so that no significant effect is printed with an interval holding 0.
        intervals = [
            _interval(float(f.beta[pos]), float(e[pos]), int(f.df[pos]), alpha)
            for f, e in zip(sizes, size_errors, strict=True)
        ]
        passing = [i for i, p in enumerate(tests) if p * len(scales) <= holm_levels[pos - 1]]
        shown = [i for i in passing if _excludes_zero(intervals[i])]
        # A delay acts within a second: on 10 s means the slope of the simulated signal is
        # matched by slow errors as much as by the delay. It is sized on the regression grid.
        fast = [i for i in shown if i == 0] if s.kind == "lag" else []
        at = (
            min(fast)
            if fast
            else max(shown)
            if shown
            else max(passing)
            if passing
            else int(np.argmin(tests))
        )
        fit, se = sizes[at], size_errors[at]
        b_std, se_std, df = float(fit.beta[pos]), float(se[pos]), int(fit.df[pos])
        coef = b_std / s.std
        p = min(1.0, tests[at] * len(scales))
        terms.append(
            _Term(
                name=s.name,
                kind=s.kind,
                coefficient=coef * s.unit,
                interval=_scaled(_interval(coef, se_std / s.std, df, alpha), s.unit),
                p_value=p,
                significant=bool(shown),
                term=coef * (s.full - centre),
                mean_shift=coef * (float(np.mean(s.full)) - centre) / scale,
                time_scale_s=scales[at].factor * dt,
                members=s.members,
                at_zero=-coef * centre,
            )
        )
    return fits, sizes, terms


def _refitted(
    subset: Sequence[int],
    scales: Sequence[_Scale],
    chosen: Sequence[_Series],
    centres: Sequence[float],
    holm_levels: Sequence[float],
    alpha: float,
    dt: float,
    scale: float,
) -> list[_Term]:
    """The terms of ``subset`` (positions in ``chosen``) fitted among themselves only."""
    _, _, terms = _fitted_terms(
        scales,
        [chosen[i] for i in subset],
        [centres[i] for i in subset],
        [holm_levels[i] for i in subset],
        alpha=alpha,
        dt=dt,
        scale=scale,
    )
    return terms


class _Fix(NamedTuple):
    """An effect's own fit to the residual, as the user adds it to the model."""

    series: FloatArray
    # Per unit of the effect's joint term's candidate, relative to the joint coefficient.
    coefficient: float
    # Rescaled signal units: the fix's value where the candidate is zero.
    constant: float
    alone: float


def _own_fix(r: FloatArray, t: _Term, *, refit: bool = False) -> _Fix:
    """The term on its own: what it removes, and the fix a user adds to the model.

    ``alone`` is what the term's own least-squares fit removes of Σr², r ≈ k · term, with the
    term as credited (a load with the mean shift it carries; the gain and the lag about their
    means: over one record a gain's mean shift is an offset's): an effect is judged by what
    it does on its own, not by a joint coefficient that a collinear term distorted.

    The fix adds c · term + b: c = 1 for a finding (``refit``: its coefficient as reported,
    fitted with the other findings), else its own fit with a constant; the constant b makes
    the mean error zero with the term, so a model whose constant already covers part of the
    term's mean is told to lower it.
    """
    total = dot(r, r)
    mean_r = float(np.mean(r))
    n = r.shape[0]
    if t.kind == "offset":
        alone = n * mean_r**2 / total if total > 0.0 else 0.0
        return _Fix(np.full(n, mean_r), 0.0, mean_r, alone)
    mean_t = float(np.mean(t.term))
    judged = t.term - mean_t if t.kind in ("gain", "lag") else t.term
    size = dot(judged, judged)
    alone = dot(judged, r) ** 2 / size / total if size > 0.0 and total > 0.0 else 0.0
    centred = t.term - mean_t
    spread = dot(centred, centred)
    if spread <= 0.0:
        return _Fix(np.full(n, mean_r), 0.0, mean_r, alone)
    c = 1.0 if refit else dot(centred, r - mean_r) / spread
    b = mean_r - c * mean_t
    return _Fix(c * t.term + b, c * t.coefficient, c * t.at_zero + b, alone)


def _least_squares_fit(r: FloatArray, columns: Sequence[FloatArray]) -> FloatArray:
    """The least-squares combination of ``columns`` closest to r (no intercept of its own)."""
    design = np.column_stack(columns)
    gram = np.einsum("ti,tj->ij", design, design)
    coef = np.linalg.pinv(gram, rcond=RCOND) @ np.einsum("ti,t->i", design, r)
    return np.asarray(design @ coef, dtype=np.float64)
