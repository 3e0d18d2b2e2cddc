"""Residual diagnosis: which effect does the model lack, and is there one at all?

Pure numpy/scipy: one aligned pair (reference, simulated) sampled every ``dt`` seconds and a
set of explanatory candidate series go in; a :class:`Diagnosis` comes out.

The residual r = reference − simulated is explained, in this order, by

1. timing, gain and offset of the simulated signal itself (headline fields), and
2. a forward selection over candidate series (measured channels, declared expressions,
   derivatives, plus the automatic ``lag`` and ``gain`` candidates), each added only when its
   coefficient is significant under a test that stays valid for strongly autocorrelated
   residuals, with a family-wise correction over the candidates tried.

Significance uses feasible GLS: the data are filtered by an AR(p) model of the residual
(Cochrane & Orcutt 1949), and the regression on the filtered data gets a Newey-West (1987) HAC
covariance with the Andrews (1991) plug-in bandwidth. (This is not the pre-whitened HAC of
Andrews & Monahan 1992, which keeps the OLS coefficients and filters only the scores.) See
``docs/diagnosis.md`` for the formulas and the interpretation of every field.

This module runs the steps in order; each step lives in a room of its own in this package.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ...errors import SpecError
from ..stats import (
    Whiteness,
    ar_model_screen,
    ar_order,
    block_means,
    dominant_frequencies,
    dot,
    effective_samples,
    ljung_box,
    screen,
)
from .candidates import _candidate_series, _grouped, _independent, _Scale, _slow_scale
from .effects import _effects
from .findings import Candidate, CandidateFinding, Diagnosis, Note
from .headline import _gain_and_offset, _timing
from .inference import _scaled
from .inputs import (
    _check_settings,
    _checked_dt,
    _checked_inputs,
    _free_name,
    _pow2_scale,
    _rescaled_candidates,
    _varies,
)
from .responses import _split_responses
from .selection import (
    _alone_findings,
    _forward_selection,
    _holm_weights,
    _joint_model,
    _rank,
    _timing_significant,
)
from .thresholds import LJUNG_BOX_LAGS, LOCAL_WINDOW_S, MIN_SHARE


def _exact_match(n: int) -> Diagnosis:
    return Diagnosis(
        lag_s=0.0,
        gain=1.0,
        gain_interval=(1.0, 1.0),
        offset=0.0,
        offset_interval=(0.0, 0.0),
        timing_significant=False,
        gain_significant=False,
        offset_significant=False,
        candidates=(),
        explained_fraction=0.0,
        remaining=Whiteness(lags=(), statistic=0.0, p_value=1.0, white=True),
        dominant_frequencies_hz=(),
        effective_samples=float(n),
        exact_match=True,
    )


def diagnose_residual(
    reference: npt.ArrayLike,
    simulated: npt.ArrayLike,
    *,
    dt: float,
    candidates: Sequence[Candidate] = (),
    max_lag_s: float | None = None,
    alpha: float = 0.05,
    max_selected: int = 5,
    max_samples: int = 20000,
    responses: Collection[str] = (),
    causes: Collection[str] = (),
    min_share: float = MIN_SHARE,
    window_s: float = LOCAL_WINDOW_S,
    groups: Sequence[Collection[str]] = (),
    in_dimension: Collection[str] = (),
    first: Collection[str] = (),
    exogenous: Collection[str] = (),
) -> Diagnosis:
    """Explain the residual r = reference − simulated by timing, gain, offset and candidates.

    Parameters
    ----------
    reference, simulated:
        The aligned measured and simulated signal, same length, finite.
    dt:
        Sample interval in seconds.
    candidates:
        Explanatory series on the same grid. Automatic ``lag`` (the slope of the simulated
        signal over the searched lag) and ``gain`` (the simulated signal) candidates are added
        unless a candidate of that kind is given.
    max_lag_s:
        Half-width of the lag search window; default min(10 s, a quarter of the record).
    alpha:
        Family-wise significance level; intervals are (1 − alpha) intervals.
    max_selected:
        At most this many candidates enter the joint model (0 to 11: the shares are exact
        over every subset of the effects and the intercept).
    max_samples:
        Longer records are reduced by block means to at most this many samples for the
        regressions and tests (explained fractions are computed at the original rate).
    responses, causes:
        Candidate names declared as responses of the scored signal (never offered as the
        missing effect) or as causes (never classified as responses or echoes).
    min_share:
        A significant effect is relevant when fixing it alone removes at least this share of
        the residual's mean square; smaller ones are minor.
    window_s:
        Window length, in seconds, over which the concentration of the residual is found.
    groups:
        Sets of candidate names that measure one effect, whatever their correlation; each is
        reported as one effect (strongly correlated candidates are grouped anyway).
    in_dimension:
        Candidate names measured in the scored signal's own physical dimension. They are
        tested first (with ``first``), and of two effects the record cannot tell apart, one of
        these is named before one that is not.
    first:
        Further candidate names tested first: the spec's declared suspects. The automatic lag
        and gain, ``in_dimension`` and these form the first family of the gatekeeping order;
        every other candidate is tested only on what the first family's effects leave.
    exogenous:
        Candidate names the vehicle cannot move (ambient temperature, elevation, time, the
        model's inputs): never classified as consequences of the scored signal.

    Returns
    -------
    Diagnosis

    Raises
    ------
    DegenerateSignalError
        Non-finite values, length mismatch, fewer than 10 samples, non-positive ``dt``, or a
        candidate that is not a finite series of the same length.
    SpecError
        Invalid ``alpha``, ``max_selected``, ``max_samples``, an unknown candidate kind or a
        duplicate candidate name.

    Notes
    -----
    *Timing.* The lag m (samples) maximises the mean-removed cross-correlation within
    ±``max_lag_s``. The ``lag`` candidate is the secant slope
    x(t) = [sim(t + d) − sim(t)] / d with d = −m·dt (the derivative when m = 0): a delay d gives
    r = d·x exactly, so its coefficient is the delay in seconds. ``timing_significant`` needs
    m ≠ 0, the ``lag`` candidate selected (below), a coefficient of the sign of −m and at least
    half a sample.

    *Gain and offset.* On the lag-aligned pair, reference ≈ gain · simulated + offset, tested by
    the filtered regression below and sized by least squares (*Sizes*). Each is *significant*
    when its p-value is below α/2 (Bonferroni over the two), its (1 − α) interval excludes 1
    (gain) or 0 (offset), and the effect is material: |gain − 1| > 0.5 %, |offset| > 0.5 % of
    the reference range.

    *Forward selection.* Candidates z_j are standardised on the regression grid; constant and
    collinear ones (R² > 1 − 10⁻⁶ on those before them) are dropped with a note. At step k
    (k = 0, 1, …) each remaining candidate with an increase of R² of at least 0.5 % is tested
    in the model r = c + Σ_selected β z + β_j z_j; those with p_j ≤ α / (m − k) (Holm 1979)
    are eligible and the one with the largest increase of R² enters.

    *Tests.* Feasible GLS (Cochrane & Orcutt 1949): the OLS residual u of the model under test
    gives AR(p) coefficients φ (p by BIC, Schwarz 1978, on the raw residual, p ≤ 10), with the
    Kendall (1954) bias (1 + 3Σφ)/n added back to Σφ, capped at 1 − 1/n. The response and every
    regressor are filtered, y*_t = y_t − Σ_i φ_i y_{t−i}, and OLS on the filtered data gets the
    Newey & West (1987) variance (X*ᵀX*)⁻¹ S (X*ᵀX*)⁻¹, S = Σ_l w_l Γ_l with Bartlett weights
    w_l = 1 − |l|/S_T and the Andrews (1991) AR(1) plug-in bandwidth S_T (GLS coefficients, not
    the OLS ones of Andrews & Monahan's 1992 pre-whitened HAC). Student-t with the effective
    degrees of freedom
    ν = n (1 − φ̄ρ)/(1 + φ̄ρ) − k, φ̄ = Σφ and ρ the lag-one autocorrelation of the regressor
    (Bretherton et al. 1999), which keeps slowly varying regressors in persistent noise honest.

    *Sizes.* Every printed coefficient and interval is least squares with the exact covariance
    (XᵀX)⁻¹XᵀΣX(XᵀX)⁻¹ under the AR model of its residual (:func:`.stats.ar_model_fit`), an
    effect's on the coarsest scale where it passes its test: filtering weighs the fast part of
    a regressor most, where timing jitter and a logged channel's noise dilute its coefficient.
    Under the gatekeeping order the first family is sized and credited among itself first.
    """
    dt = _checked_dt(dt)
    _check_settings(alpha, max_selected, max_samples)
    if not 0.0 <= min_share < 1.0:
        raise SpecError(f"min_share must lie in [0, 1), got {min_share}")
    ref, sim, user, names = _checked_inputs(reference, simulated, candidates)
    n = ref.shape[0]
    if not np.any(ref - sim):
        return _exact_match(n)
    # Exact power-of-two rescaling keeps sums of squares of 1e200-sized or 1e-200-sized signals
    # inside float64; fractions, p-values, gain and delay do not depend on it.
    s_sig = _pow2_scale(max(float(np.max(np.abs(ref))), float(np.max(np.abs(sim)))))
    ref = ref * s_sig
    sim = sim * s_sig
    user, units = _rescaled_candidates(user, s_sig)
    notes: list[Note] = []
    sim_varies = _varies(sim)

    lag, max_lag = _timing(ref, sim, dt, max_lag_s, sim_varies)
    lag_s = lag * dt
    # The candidates are analysed where sim(t − lag) exists, so that the lag candidate is exact
    # on every sample it is fitted to.
    window = slice(max(0, lag), n + min(0, lag))
    r = (ref - sim)[window]
    n_w = r.shape[0]
    factor = max(1, math.ceil(n_w / max_samples))
    r_g = block_means(r, factor)
    order = ar_order(r_g - float(np.mean(r_g)))

    head = _gain_and_offset(ref, sim, lag, order, alpha, max_samples, sim_varies)
    if not sim_varies:
        notes.append(Note("constant_simulation"))

    user, echoes = _split_responses(ref, sim, dt, user, responses, causes, exogenous)
    series = _grouped(
        _candidate_series(sim, lag, dt, window, factor, user, units, names),
        r_g,
        groups,
        in_dimension,
    )
    kept, z_rows = _independent(series, r_g.shape[0], notes)
    m = len(kept)
    # Alone: every candidate with an intercept.
    ones = np.ones((r_g.shape[0], 1))
    alone = screen(r_g, ones, z_rows, order) if m else None
    alone_sizes = ar_model_screen(r_g, ones, z_rows, order) if m else None
    scales = [_Scale(factor, r_g, z_rows, order)]
    slow = _slow_scale(r, kept, dt, factor) if m else None
    if slow is not None:
        scales.append(slow)
    leading = set(in_dimension) | set(first)
    named = np.array([bool(leading & {s.name, *s.members}) for s in kept], dtype=bool)
    # The automatic lag and gain are in the signal's dimension: with a first family, they
    # belong to it. Without one (no unit or suspect given), there is no order to keep.
    family = named | np.array([s.kind in ("lag", "gain") for s in kept], dtype=bool)
    gatekeeping = bool(np.any(named))
    weights = _holm_weights(family if gatekeeping else np.zeros(len(kept), dtype=bool))
    selected, holm_levels, bases = _forward_selection(
        scales,
        alpha=alpha,
        max_selected=max_selected,
        weights=weights,
        first=family if gatekeeping else None,
    )
    base = bases[0]

    findings, explained, remaining_full, remaining_grid = _joint_model(
        r, r_g, kept, selected, holm_levels, base, order, alpha
    )
    findings.extend(_alone_findings(r, kept, selected, alone, alone_sizes, alpha, weights))
    mean_sq = dot(r, r) / n_w
    offset_finding = CandidateFinding(
        name=_free_name("offset", names),
        kind="offset",
        explained_fraction=min(1.0, float(np.mean(r)) ** 2 / mean_sq),
        joint_explained_fraction=None,
        coefficient=head.offset / s_sig,
        interval=_scaled(head.offset_interval, 1.0 / s_sig),
        p_value=head.offset_p,
        significant=head.offset_significant,
        selected=head.offset_significant,
        rank=0,
    )
    ordered = _rank([*findings, offset_finding])

    remaining = ljung_box(remaining_grid, LJUNG_BOX_LAGS, alpha=alpha)
    frequencies = dominant_frequencies(remaining_full - float(np.mean(remaining_full)), dt)
    effective = effective_samples(r_g, order)
    if factor > 1:
        notes.append(Note("decimated", samples=factor, seconds=dt * factor))

    effects, lambdas, predicted, where = _effects(
        ref[window],
        sim[window],
        scales,
        kept,
        selected,
        holm_levels,
        alpha=alpha,
        dt=dt,
        start_s=window.start * dt,
        min_share=min_share,
        window_s=window_s,
        scale=s_sig,
        offset_name=_free_name("offset", names),
        in_units=set(in_dimension),
        leading=leading if gatekeeping else set(),
    )
    # A selected candidate is an effect: the table shows the effect's numbers, so that one
    # effect reads the same everywhere.
    as_effect = {e.name: e for e in effects}
    ordered = [
        replace(
            f,
            coefficient=e.coefficient,
            interval=e.interval,
            p_value=e.p_value,
            significant=e.significant,
        )
        if f.selected and (e := as_effect.get(f.name)) is not None
        else f
        for f in ordered
    ]
    timing_significant = _timing_significant(ordered, lag, dt)
    return Diagnosis(
        lag_s=lag_s,
        gain=head.gain,
        gain_interval=head.gain_interval,
        offset=head.offset / s_sig,
        offset_interval=_scaled(head.offset_interval, 1.0 / s_sig),
        timing_significant=timing_significant,
        gain_significant=head.gain_significant,
        offset_significant=head.offset_significant,
        candidates=tuple(ordered),
        explained_fraction=explained,
        remaining=remaining,
        dominant_frequencies_hz=frequencies,
        effective_samples=effective,
        notes=tuple(notes),
        effects=effects,
        responses=echoes,
        min_share=min_share,
        lambdas=lambdas,
        predicted=predicted,
        localisation=where,
        max_lag_s=max_lag * dt,
        lag_at_bound=max_lag > 0 and abs(lag) >= max_lag,
    )
