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
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from ..errors import DegenerateSignalError, SpecError
from .importance import MAX_TERMS, explained_sums, shapley_from_sums
from .lag import search_lag
from .local import concentration, fixed_windows, group_lambdas, segment_sums
from .stats import (
    RCOND,
    HacFit,
    Screen,
    Whiteness,
    ar_model_fit,
    ar_model_screen,
    ar_order,
    block_means,
    dominant_frequencies,
    dot,
    effective_samples,
    hac_fit,
    ljung_box,
    orthonormal,
    project_out,
    screen,
)

__all__ = [
    "Candidate",
    "CandidateFinding",
    "Diagnosis",
    "Effect",
    "Localisation",
    "Response",
    "Whiteness",
    "diagnose_residual",
    "ljung_box",
]

FloatArray = npt.NDArray[np.float64]
CandidateKind = Literal["declared", "channel", "derivative", "lag", "gain", "offset"]

#: A gain error smaller than this (relative) is not material, however significant.
GAIN_MATERIALITY = 0.005
#: An offset smaller than this fraction of the reference range is not material.
OFFSET_MATERIALITY = 0.005
#: A candidate must raise the explained variance by at least this much to be selected.
MIN_EXPLAINED_INCREASE = 0.005
#: A finding is relevant when fixing it alone removes at least this share of the residual's
#: mean square. 5 % lowers the RMS error by 2.5 % (√0.95): anything smaller cannot move λ4 by
#: more than a fortieth of its distance to 1, so it is listed as minor rather than as a cause.
MIN_SHARE = 0.05
#: A channel is a response (a consequence of what the model reproduces) when the simulated
#: signal explains at least this share of its variance ...
RESPONSE_MIN_R2 = 0.1
#: ... and the residual adds less than this fraction of that share on top of it, plus the
#: fraction a response to the measured signal gets from the residual anyway: one that moves
#: with the simulated part and the residual alike gains about var(r) / var(sim) of what the
#: simulation explains. A missing load moves with the residual only.
RESPONSE_RESIDUAL_RATIO = 0.25
#: A channel is an echo of the scored signal (an instrument of it, its derivative or its
#: integral) when, on block means of :data:`SLOW_SCALE_S`, the measured signal explains at least
#: this share of its variance (instrument, derivative) ...
ECHO_MIN_R2 = 0.8
#: ... or this share of the variance of its increments (integral: a state of charge) ...
ECHO_INCREMENT_MIN_R2 = 0.5
#: ... and the simulated signal explains at least this fraction of that: a missing load that
#: makes most of the measured signal is explained by it too, but not by the simulation.
ECHO_SIMULATED_RATIO = 0.5
#: A channel is an echo, too, when the measured signal as a whole explains at least this share
#: of its variance on those block means ...
ECHO_WHOLE_MIN_R2 = 0.25
#: ... and at least this fraction of what its two parts (the simulated signal and the residual,
#: with coefficients of their own) explain: a response to the measured power (a battery that
#: warms with the current, a state of charge's rate) weighs both parts alike, while a missing
#: load moves with the residual only.
ECHO_WHOLE_RATIO = 0.7
#: A channel whose cross-correlation with the measured signal peaks with the channel ahead by
#: at least RESPONSE_MIN_LEAD_S, within ±RESPONSE_LEAD_WINDOW_S, is treated as an input (the
#: driver acts, then the power follows), however well the measured signal explains it. A
#: shorter lead is within the timing jitter of CAN logging (frames at 10–100 Hz) and says
#: nothing about direction.
RESPONSE_LEAD_WINDOW_S = 2.0
RESPONSE_MIN_LEAD_S = 0.2
#: Windows over which the diagnosis says where the residual concentrates.
LOCAL_WINDOW_S = 30.0
#: Candidates whose series correlate at least this strongly (either sign) measure the same
#: thing: a heater's current, its power on two buses and its requested power are one effect.
GROUP_MIN_CORRELATION = 0.9
#: Besides the regression grid, every candidate is also tested on block means of this length.
#: A missing load acts over tens of seconds to minutes, while most of a model's 10 Hz residual
#: is its own fast dynamics error; pre-whitening that residual is nearly a difference filter
#: and removes the slow variation the load lives in. Block means of 10 s keep it.
SLOW_SCALE_S = 10.0
#: The slow scale is used only when the record holds at least this many of its blocks.
MIN_SLOW_BLOCKS = 20
#: Two effects are interchangeable on a record when what they explain in common is at least
#: this fraction of what the smaller of the two explains alone; the smaller one is then no
#: finding of its own (a gain and an offset can mimic a slowly varying load, a warming
#: battery can mimic a heater that is turned down).
INTERCHANGEABLE_OVERLAP = 0.5
#: The characteristics the diagnosis predicts after a fix.
PREDICTED_CHARACTERISTICS: tuple[str, ...] = ("mae", "rms")
#: Ljung-Box lags, in samples of the (possibly decimated) regression grid.
LJUNG_BOX_LAGS: tuple[int, ...] = (10, 20)

# A standardised candidate whose variance left after projecting out the ones already kept is
# below this fraction is a linear combination of them (|multiple correlation| > 0.999 999 5).
_COLLINEAR = 1e-6
_DEFAULT_MAX_LAG_S = 10.0
_KINDS: tuple[str, ...] = ("declared", "channel", "derivative", "lag", "gain", "offset")
#: The generic terms, which describe the simulated signal itself rather than name a cause.
GENERIC_KINDS: tuple[str, ...] = ("lag", "gain", "offset")
# Which member names a group when members explain about as much: the spec's own expression
# (the user's words), then a logged channel, then a derivative.
_NAMING_PREFERENCE = {"declared": 0, "channel": 1, "derivative": 2}
_NAMING_TOLERANCE = 0.05
# A member in the scored signal's own dimension names its group when it explains at least this
# fraction of what the best member does.
_DIMENSION_NAMING_SHARE = 0.5


@dataclass(frozen=True)
class Candidate:
    """One explanatory series on the aligned grid of the residual.

    Attributes
    ----------
    name:
        Unique label, used in findings and the summary.
    kind:
        Where the series comes from: a ``"declared"`` expression, a measured ``"channel"``,
        a ``"derivative"`` of one, or one of the automatic kinds ``"lag"``, ``"gain"`` and
        ``"offset"``.
    values:
        The series, one value per sample of the reference.
    """

    name: str
    kind: CandidateKind
    values: npt.NDArray[Any]


@dataclass(frozen=True)
class CandidateFinding:
    """What one candidate explains of the residual.

    Attributes
    ----------
    name, kind:
        As in the :class:`Candidate` (``kind="offset"`` is the constant term).
    explained_fraction:
        Centred R² of the residual regressed on this candidate alone plus an intercept, at the
        original sample rate. For the offset: the share of the residual's mean square carried
        by its mean, mean(r)² / mean(r²).
    joint_explained_fraction:
        R² of the residual on all candidates selected up to and including this one; ``None``
        when the candidate was not selected.
    coefficient:
        Effect size in the candidate's own units: r ≈ coefficient · candidate. For ``lag`` it is
        the delay of the simulated signal in seconds (positive: simulated late), for ``gain``
        it is gain − 1, for ``offset`` the offset in the signal's units. From the final joint
        model when selected, otherwise from the candidate alone.
    interval:
        (1 − alpha) confidence interval of the coefficient (pre-whitened HAC).
    p_value:
        Two-sided p-value of coefficient = 0, unadjusted for multiplicity.
    significant:
        ``p_value`` is below the family-wise corrected level (Holm level at selection for
        selected candidates, Bonferroni over all candidates otherwise).
    selected:
        The candidate entered the joint model (for the offset: it is significant and material).
    rank:
        Position in :attr:`Diagnosis.candidates`, 1 = best.
    """

    name: str
    kind: str
    explained_fraction: float
    joint_explained_fraction: float | None
    coefficient: float
    interval: tuple[float, float]
    p_value: float
    significant: bool
    selected: bool
    rank: int


@dataclass(frozen=True)
class Effect:
    """One effect the residual holds, fitted jointly with the intercept and the others.

    Attributes
    ----------
    name, kind:
        As in the :class:`CandidateFinding`; ``kind="offset"`` is the intercept left once the
        other effects have taken the mean shift they explain.
    coefficient, interval, p_value:
        From the joint model at the time scale where the effect is tested most sharply (the
        p-value times the number of scales), in the signal's units per unit of the candidate
        (for the offset: in the signal's units).
    share:
        Its Shapley (LMG) share of the residual's sum of squares at the original rate
        (:mod:`.importance`): never negative, and the shares of all effects add up to what
        they explain together, whatever their order.
    offset_explained:
        The mean shift this effect is credited with, in the signal's units: coefficient × mean
        of the candidate when that brings the offset left over closer to zero, else 0. The gain
        always carries its mean (the offset is the one at simulated = 0, as in the headline
        fit); the lag never does.
    significant:
        The coefficient passed its family-wise level (weighted Holm level at selection; α/2
        and material for the offset).
    relevant:
        A finding: significant, ``share`` and ``alone_share`` at least the minimum share, and
        no larger finding can stand in for it.
    predicted:
        λ3 and λ4 of the signal if this effect alone were added to the model, with the
        coefficient above.
    hot_share:
        Share of the residual's squared error inside the hot windows that this effect removes;
        ``None`` when the error does not concentrate.
    members:
        The other candidates that measure the same thing; this one names the effect.
    interchangeable:
        The effects that can stand in for it on this record, and it for them.
    stands_in_for:
        For a significant effect that is no finding of its own: the findings among
        ``interchangeable`` that are named instead of it.
    time_scale_s:
        The block length its coefficient was estimated on.
    alone_share:
        What its own least-squares fit removes of the residual's sum of squares about its
        mean: what the effect does on its own, whatever a correlated term did to its joint
        coefficient.
    fix_coefficient, fix_constant:
        The fix as a user applies it: add ``fix_coefficient`` × the candidate and
        ``fix_constant`` (in the signal's units) to the model's output. The coefficient is the
        effect's own least-squares fit to the residual; the constant makes the mean error
        zero with it, so a model whose constant term already covers part of the effect's
        mean is told to lower that term. ``predicted`` are the λ of exactly that fix. For the
        gain: the model's output times 1 + ``fix_coefficient``, plus the constant; for the
        offset and the lag, the constant and the delay.
    """

    name: str
    kind: str
    coefficient: float
    interval: tuple[float, float]
    p_value: float
    share: float
    offset_explained: float
    significant: bool
    relevant: bool
    predicted: Mapping[str, float]
    hot_share: float | None
    members: tuple[str, ...] = ()
    interchangeable: tuple[str, ...] = ()
    stands_in_for: tuple[str, ...] = ()
    time_scale_s: float = 0.0
    alone_share: float = 0.0
    fix_coefficient: float = 0.0
    fix_constant: float = 0.0


@dataclass(frozen=True)
class Response:
    """A channel that moves with the scored signal, probably a consequence rather than a cause.

    Attributes
    ----------
    name, kind:
        As in the :class:`Candidate`.
    reason:
        ``"declared"`` (the spec lists it under ``responses:``), ``"echo"`` (an instrument,
        derivative or integral of the measured signal), ``"follows"`` (it moves with the
        simulated signal, and the residual adds little) or ``"reproduced"`` (as ``"follows"``,
        but it leads the measured signal: a cause the model reproduces through its inputs).
    measured_r2:
        ``"follows"``, ``"reproduced"``: share of the channel's variance the simulated signal
        explains.
        ``"echo"``: share of the variance of the channel (or of its increments) the measured
        signal explains on block means of :data:`SLOW_SCALE_S`.
    residual_r2:
        What the residual adds to that share (``"follows"``).
    lead_s:
        Lead of the channel over the measured signal at the peak of their |cross-correlation|
        within ±2 s (negative: the channel follows).
    explains:
        Share of the residual's variance the channel explains alone: what it would have been
        offered as, had it not been set apart.
    """

    name: str
    kind: str
    reason: str
    measured_r2: float
    residual_r2: float
    lead_s: float
    explains: float


@dataclass(frozen=True)
class Localisation:
    """Where in time the residual concentrates (:func:`pytest_hevval.core.local.concentration`).

    Attributes
    ----------
    window_s:
        Length of the windows.
    error_share, time_share:
        Share of the squared residual in the hot windows, and share of the time they take.
    spans_s:
        The hot stretches (start, stop) in seconds, worst first.
    windows:
        Number of hot windows.
    """

    window_s: float
    error_share: float
    time_share: float
    spans_s: tuple[tuple[float, float], ...]
    windows: int


@dataclass(frozen=True)
class Diagnosis:
    """Where a residual comes from. Every field is explained in ``docs/diagnosis.md``."""

    lag_s: float
    gain: float
    gain_interval: tuple[float, float]
    offset: float
    offset_interval: tuple[float, float]
    timing_significant: bool
    gain_significant: bool
    offset_significant: bool
    candidates: tuple[CandidateFinding, ...]
    explained_fraction: float
    remaining: Whiteness
    dominant_frequencies_hz: tuple[float, ...]
    effective_samples: float
    notes: tuple[str, ...] = ()
    effects: tuple[Effect, ...] = ()
    responses: tuple[Response, ...] = ()
    min_share: float = MIN_SHARE
    lambdas: Mapping[str, float] = field(default_factory=dict)
    predicted: Mapping[str, float] = field(default_factory=dict)
    localisation: Localisation | None = None
    #: The residual is zero: nothing to diagnose.
    exact_match: bool = False
    #: Half-width of the lag search, in seconds.
    max_lag_s: float = 0.0
    #: The lag found lies on the edge of the search: the true lag may be larger.
    lag_at_bound: bool = False

    @property
    def relevant(self) -> tuple[Effect, ...]:
        """The effects that are significant and explain at least the minimum share."""
        return tuple(e for e in self.effects if e.relevant)

    @property
    def minor(self) -> tuple[Effect, ...]:
        """Significant effects that are no finding, and that no finding stands in for: they
        explain less than the minimum share, or do not help on their own."""
        return tuple(e for e in self.effects if _is_minor(e))

    @property
    def stand_ins(self) -> tuple[Effect, ...]:
        """Significant effects that a finding can stand in for on this record."""
        return tuple(e for e in self.effects if e.stands_in_for)


# ---------------------------------------------------------------------------------------------
# Diagnosis
# ---------------------------------------------------------------------------------------------


def _as_signal(values: npt.ArrayLike, what: str) -> FloatArray:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DegenerateSignalError(f"{what} is not numeric: {exc}") from exc
    if array.ndim != 1:
        raise DegenerateSignalError(f"{what} must be one-dimensional, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise DegenerateSignalError(
            f"{what} contains {bad} NaN or infinite value(s)",
            hint="fill or drop the gaps before diagnosing the residual",
        )
    return array


@dataclass
class _Series:
    name: str
    kind: str
    full: FloatArray
    grid: FloatArray
    mean: float
    std: float
    # Multiplies a coefficient fitted on the rescaled data to give it in the caller's units.
    unit: float
    # Other candidates that measure the same thing (see _grouped); this one names the effect.
    members: tuple[str, ...] = ()


def _excludes_zero(interval: tuple[float, float]) -> bool:
    return not interval[0] <= 0.0 <= interval[1]


def _interval(beta: float, se: float, df: int, alpha: float) -> tuple[float, float]:
    from scipy import stats  # over a second to import; scoring never needs it

    half = float(stats.t.ppf(1.0 - alpha / 2.0, df)) * se
    return (beta - half, beta + half)


def _full_rate_r2(r: FloatArray, columns: Sequence[FloatArray]) -> float:
    """Centred R² of r on an intercept and ``columns``, from their Gram matrix."""
    if not columns:
        return 0.0
    rc = r - float(np.mean(r))
    total = dot(rc, rc)
    if total <= 0.0:
        return 0.0
    centred = [c - float(np.mean(c)) for c in columns]
    k = len(centred)
    gram = np.empty((k, k))
    cross = np.empty(k)
    for i in range(k):
        cross[i] = dot(centred[i], rc)
        for j in range(i, k):
            gram[i, j] = gram[j, i] = dot(centred[i], centred[j])
    coef = np.linalg.pinv(gram, rcond=RCOND) @ cross
    return float(min(max(float(coef @ cross) / total, 0.0), 1.0))


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
    notes: list[str] = []
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
        notes.append("the simulated signal is constant: gain and lag cannot be estimated")

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
        notes.append(f"regressions use block means of {factor} samples ({dt * factor:g} s)")

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


# -- the steps of diagnose_residual, in order ---------------------------------------------------


def _checked_dt(dt: Any) -> float:
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating, np.integer)):
        raise DegenerateSignalError(f"dt must be a number of seconds, got {dt!r}")
    if not math.isfinite(float(dt)) or float(dt) <= 0.0:
        raise DegenerateSignalError(f"dt must be a positive, finite number of seconds, got {dt}")
    return float(dt)


def _check_settings(alpha: float, max_selected: int, max_samples: int) -> None:
    if not 0.0 < alpha < 1.0:
        raise SpecError(f"alpha must lie strictly between 0 and 1, got {alpha}")
    if not 0 <= max_selected < MAX_TERMS:
        # The shares are exact over every subset of the effects and the intercept.
        raise SpecError(f"max_selected must lie between 0 and {MAX_TERMS - 1}, got {max_selected}")
    if max_samples < 10:
        raise SpecError(f"max_samples must be at least 10, got {max_samples}")


_UserSeries = list[tuple[str, str, FloatArray]]


def _checked_inputs(
    reference: npt.ArrayLike, simulated: npt.ArrayLike, candidates: Sequence[Candidate]
) -> tuple[FloatArray, FloatArray, _UserSeries, set[str]]:
    """The two signals and the user's candidates as finite float64 series of one length."""
    ref = _as_signal(reference, "reference")
    sim = _as_signal(simulated, "simulated")
    if ref.shape[0] != sim.shape[0]:
        raise DegenerateSignalError(
            f"reference has {ref.shape[0]} samples but simulated has {sim.shape[0]}",
            hint="align both signals on one time grid first",
        )
    n = ref.shape[0]
    if n < 10:
        raise DegenerateSignalError(f"at least 10 samples are needed, got {n}")
    names: set[str] = set()
    for cand in candidates:
        if cand.kind not in _KINDS:
            raise SpecError(
                f"candidate {cand.name!r} has kind {cand.kind!r}; "
                f"expected one of {', '.join(_KINDS)}"
            )
        if cand.name in names:
            raise SpecError(f"candidate name {cand.name!r} is used twice")
        names.add(cand.name)
    user = [
        (c.name, str(c.kind), _as_signal(c.values, f"candidate {c.name!r}")) for c in candidates
    ]
    for name, _, values in user:
        if values.shape[0] != n:
            raise DegenerateSignalError(
                f"candidate {name!r} has {values.shape[0]} samples, the signals have {n}",
                key=name,
            )
    return ref, sim, user, names


def _rescaled_candidates(user: _UserSeries, s_sig: float) -> tuple[_UserSeries, dict[str, float]]:
    """Each candidate scaled by its own power of two; ``units`` turns coefficients back."""
    units: dict[str, float] = {}
    scaled: _UserSeries = []
    for name, kind, values in user:
        c = _pow2_scale(np.max(np.abs(values), initial=0.0))
        units[name] = c / s_sig
        scaled.append((name, kind, values * c))
    return scaled, units


def _timing(
    ref: FloatArray, sim: FloatArray, dt: float, max_lag_s: float | None, sim_varies: bool
) -> tuple[int, int]:
    """The lag (samples) of the peak mean-removed cross-correlation, and the half-width of
    the search (samples)."""
    n = ref.shape[0]
    window_s = _DEFAULT_MAX_LAG_S if max_lag_s is None else float(max_lag_s)
    # At least 10 samples must remain where both records overlap at the searched lag.
    max_lag = int(min(max(window_s, 0.0) / dt, (n - 10) if max_lag_s is not None else n // 4))
    # A constant signal correlates equally with every shift: there is no lag to find.
    return (search_lag(ref, sim, max_lag).lag if sim_varies and _varies(ref) else 0), max_lag


@dataclass(frozen=True)
class _Headline:
    """Gain and offset of reference ≈ gain · simulated + offset on the lag-aligned pair."""

    gain: float
    gain_interval: tuple[float, float]
    gain_significant: bool
    offset: float
    offset_interval: tuple[float, float]
    offset_p: float
    offset_significant: bool


def _gain_and_offset(
    ref: FloatArray,
    sim: FloatArray,
    lag: int,
    order: int,
    alpha: float,
    max_samples: int,
    sim_varies: bool,
) -> _Headline:
    n = ref.shape[0]
    if lag >= 0:
        ref_a, sim_a = ref[lag:], sim[: n - lag]
    else:
        ref_a, sim_a = ref[: n + lag], sim[-lag:]
    factor_a = max(1, math.ceil(ref_a.shape[0] / max_samples))
    ref_g = block_means(ref_a, factor_a)
    sim_g = block_means(sim_a, factor_a)
    ref_range = float(np.ptp(ref)) or float(np.max(np.abs(ref))) or 1.0
    design = (
        np.column_stack([np.ones_like(sim_g), sim_g])
        if sim_varies
        else np.ones((sim_g.shape[0], 1))
    )
    response = ref_g if sim_varies else ref_g - sim_g
    # The simulated signal is no candidate that could match the residual by chance: tested
    # and sized by the same least-squares fit (see _fitted_terms for why not the filtered one).
    head = ar_model_fit(response, design, order)
    head_se = np.sqrt(np.maximum(np.diag(head.cov), 0.0))
    offset = float(head.beta[0])
    offset_interval = _interval(offset, float(head_se[0]), int(head.df[0]), alpha)
    offset_p = _p_value(offset, float(head_se[0]), int(head.df[0]))
    # Gain and offset are two tests of one question ("is the simulated signal itself off?"):
    # Bonferroni over the pair keeps the chance of a false headline at most alpha.
    headline_level = alpha / 2.0
    offset_significant = (
        offset_p <= headline_level
        and not (offset_interval[0] <= 0.0 <= offset_interval[1])
        and abs(offset) > OFFSET_MATERIALITY * ref_range
    )
    if not sim_varies:
        return _Headline(
            1.0, (1.0, 1.0), False, offset, offset_interval, offset_p, offset_significant
        )
    gain = float(head.beta[1])
    gain_se = float(head_se[1])
    gain_interval = _interval(gain, gain_se, int(head.df[1]), alpha)
    gain_significant = (
        _p_value(gain - 1.0, gain_se, int(head.df[1])) <= headline_level
        and not (gain_interval[0] <= 1.0 <= gain_interval[1])
        and abs(gain - 1.0) > GAIN_MATERIALITY
    )
    return _Headline(
        gain, gain_interval, gain_significant, offset, offset_interval, offset_p, offset_significant
    )


def _candidate_series(
    sim: FloatArray,
    lag: int,
    dt: float,
    window: slice,
    factor: int,
    user: _UserSeries,
    units: Mapping[str, float],
    names: set[str],
) -> list[_Series]:
    """The automatic lag and gain candidates, then the user's, on the analysis window."""
    kinds = {kind for _, kind, _ in user}
    auto: _UserSeries = []
    # A user channel may already be called "lag" or "gain"; the automatic one then steps aside.
    if "lag" not in kinds:
        auto.append((_free_name("lag", names), "lag", _delay_slope(sim, lag, dt)[window]))
    if "gain" not in kinds:
        auto.append((_free_name("gain", names), "gain", sim[window]))
    series: list[_Series] = []
    for label, kind, values in [*auto, *((a, b, v[window]) for a, b, v in user)]:
        grid = block_means(values, factor)
        unit = units.get(label, 1.0)
        series.append(
            _Series(label, kind, values, grid, float(np.mean(grid)), float(np.std(grid)), unit)
        )
    return series


def _independent(
    series: list[_Series], ng: int, notes: list[str]
) -> tuple[list[_Series], FloatArray]:
    """Candidates that are neither constant nor collinear, and their standardised rows."""
    usable: list[_Series] = []
    for s in series:
        scale = max(float(np.max(np.abs(s.grid))), 1e-300)
        if s.std <= 1e-12 * scale:
            notes.append(f"candidate {s.name!r} is constant and was dropped")
        else:
            usable.append(s)
    # Sequential Cholesky of the Gram matrix of [1, z₁, z₂, …]: the pivot of z_j is the part
    # of its variance left after projecting out the constant and every candidate kept before
    # it, so one pass finds all collinear ones; a dropped candidate adds no pivot.
    standardised = np.empty((len(usable) + 1, ng))
    standardised[0] = 1.0 / math.sqrt(ng)
    for i, s in enumerate(usable):
        standardised[i + 1] = (s.grid - s.mean) / s.std
    from scipy import linalg as sla  # a tenth of a second to import; scoring never needs it

    gram = np.einsum("it,jt->ij", standardised, standardised)
    factor_rows = np.zeros_like(gram)
    factor_rows[0, 0] = math.sqrt(gram[0, 0])
    kept: list[_Series] = []
    kept_rows: list[int] = [0]
    for i, s in enumerate(usable, start=1):
        cols = np.asarray(kept_rows)
        below = sla.solve_triangular(
            factor_rows[np.ix_(cols, cols)], gram[cols, i], lower=True, check_finite=False
        )
        pivot = gram[i, i] - float(np.sum(below**2))
        if pivot / gram[i, i] >= _COLLINEAR:
            factor_rows[i, cols] = below
            factor_rows[i, i] = math.sqrt(pivot)
            kept.append(s)
            kept_rows.append(i)
            continue
        corr = np.abs(gram[kept_rows[1:], i]) / ng
        best = int(np.argmax(corr)) if kept else -1
        if best >= 0 and corr[best] ** 2 >= 1.0 - _COLLINEAR:
            notes.append(f"candidate {s.name!r} duplicates {kept[best].name!r} and was dropped")
        else:
            notes.append(
                f"candidate {s.name!r} is (nearly) a linear combination of the candidates "
                "before it and was dropped"
            )
    rows = kept_rows[1:]
    z_rows = np.ascontiguousarray(standardised[rows]) if kept else np.zeros((0, ng))
    return kept, z_rows


def _grouped(
    series: list[_Series],
    r_g: FloatArray,
    declared: Sequence[Collection[str]] = (),
    in_dimension: Collection[str] = (),
) -> list[_Series]:
    """One series per effect: candidates that measure the same thing become one group.

    Candidates are taken by how much of the residual each explains alone, best first; each
    joins the first group whose leading member it correlates with at least
    :data:`GROUP_MIN_CORRELATION` (either sign), or starts a group of its own. A group is named
    by its best member (the spec's own expression, then a logged channel, when members explain
    within 5 % as much; a member in the scored signal's dimension when it explains at least
    half as much) and lists the others as ``members``. Only that member enters the
    selection: offered side by side, near copies split one effect between them with opposite
    signs, and none is credited with it. The automatic lag and gain are never grouped. The
    spec's declared groups are groups from the start, whatever their correlation.
    """
    pool = [i for i, s in enumerate(series) if s.kind not in GENERIC_KINDS and s.std > 0.0]
    if len(pool) < 2:
        return series
    ng = r_g.shape[0]
    rows = np.stack([(series[i].grid - series[i].mean) / series[i].std for i in pool])
    rc = r_g - float(np.mean(r_g))
    sst = dot(rc, rc)
    score = (rows @ rc) ** 2 / (ng * sst) if sst > 0.0 else np.zeros(len(pool))
    corr = np.abs(rows @ rows.T) / ng
    order = [int(a) for a in np.argsort(-score, kind="stable")]
    position = {series[i].name: a for a, i in enumerate(pool)}
    groups: list[list[int]] = []
    placed: set[int] = set()
    for names in declared:
        found = sorted((position[n] for n in names if n in position), key=order.index)
        if found:
            groups.append(found)
            placed.update(found)
    for a in order:
        if a in placed:
            continue
        home = next((g for g in groups if corr[a, g[0]] >= GROUP_MIN_CORRELATION), None)
        if home is None:
            groups.append([int(a)])
        else:
            home.append(int(a))
    leaders: dict[int, _Series] = {}
    dropped: set[int] = set()
    for g in groups:
        best = float(score[g[0]])

        def naming(a: int, best: float = best) -> tuple[int, int, int, float]:
            near = score[a] >= (1.0 - _NAMING_TOLERANCE) * best
            kind = series[pool[a]].kind
            return (
                0 if kind == "declared" and near else 1,
                # A coarse or stuck load channel still names the effect before a temperature
                # that follows the load more smoothly, as long as it explains half as much.
                0
                if series[pool[a]].name in in_dimension
                and score[a] >= _DIMENSION_NAMING_SHARE * best
                else 1,
                _NAMING_PREFERENCE.get(kind, 3) if near else 9,
                -float(score[a]),
            )

        lead = min(g, key=naming)
        members = tuple(series[pool[a]].name for a in g if a != lead)
        leaders[pool[lead]] = replace(series[pool[lead]], members=members)
        dropped.update(pool[a] for a in g if a != lead)
    return [leaders.get(i, s) for i, s in enumerate(series) if i not in dropped]


@dataclass(frozen=True)
class _Scale:
    """The residual and the standardised candidates on one grid of block means."""

    factor: int
    r: FloatArray
    z_rows: FloatArray
    order: int


def _slow_scale(r: FloatArray, kept: Sequence[_Series], dt: float, factor: int) -> _Scale | None:
    """The grid of :data:`SLOW_SCALE_S` block means, when it is coarser than the regression
    grid and the record holds at least :data:`MIN_SLOW_BLOCKS` of its blocks."""
    slow = max(1, round(SLOW_SCALE_S / dt))
    if slow <= factor or r.shape[0] // slow < MIN_SLOW_BLOCKS:
        return None
    r_s = block_means(r, slow)
    rows = np.empty((len(kept), r_s.shape[0]))
    for i, s in enumerate(kept):
        block = block_means(s.full, slow)
        spread = float(np.std(block))
        rows[i] = (block - float(np.mean(block))) / spread if spread > 0.0 else 0.0
    return _Scale(slow, r_s, rows, ar_order(r_s - float(np.mean(r_s))))


def _holm_weights(first: npt.NDArray[np.bool_]) -> FloatArray:
    """Weights of the weighted Holm procedure: the first family of the gatekeeping order (the
    automatic terms, the loads in the signal's dimension and the spec's declared suspects)
    shares half of the level, every other candidate the other half; equal weights when there
    are only one or the other."""
    d = int(np.count_nonzero(first))
    if d == 0 or d == first.shape[0]:
        return np.ones(first.shape[0])
    return np.where(first, (first.shape[0] - d) / d, 1.0)


def _forward_selection(
    scales: Sequence[_Scale],
    *,
    alpha: float,
    max_selected: int,
    weights: FloatArray,
    first: npt.NDArray[np.bool_] | None = None,
) -> tuple[list[int], list[float], list[FloatArray]]:
    """Holm-guarded forward selection; (selected rows, their levels, the final design per scale).

    Gatekeeping order: while a candidate of the first family (``first``) passes, only those
    can enter; the others are tested on what the first family's selected effects leave. A
    temperature that follows a heater then explains only what the heater's power does not.

    A candidate is tested at every scale and passes when its smallest p-value, times the number
    of scales (Bonferroni), is under its weighted Holm level α·w_j / Σ w of the candidates not
    yet selected (Holm 1979): an effect counts at the time scale where it acts, and the user's
    declared suspects weigh more than the many channels tried automatically. The largest
    increase of R² on the regression grid (the first scale) picks among those that pass.
    """
    fine = scales[0]
    r_g = fine.r
    ng = r_g.shape[0]
    m = fine.z_rows.shape[0]
    rc_g = r_g - float(np.mean(r_g))
    sst_g = dot(rc_g, rc_g)
    selected: list[int] = []
    holm_levels: list[float] = []
    remaining_idx = list(range(m))
    bases = [np.ones((sc.r.shape[0], 1)) for sc in scales]
    while remaining_idx and len(selected) < max_selected and sst_g > 0.0:
        levels = alpha * weights / float(np.sum(weights[remaining_idx]))
        q = orthonormal(bases[0])
        resid = project_out(r_g[None, :], q)[0]
        z_rem = fine.z_rows[remaining_idx]
        z_perp = project_out(z_rem, q)
        zz = np.einsum("jt,jt->j", z_perp, z_perp)
        with np.errstate(invalid="ignore", divide="ignore"):
            gain_r2 = np.where(
                zz / ng > _COLLINEAR, np.einsum("jt,t->j", z_perp, resid) ** 2 / zz / sst_g, 0.0
            )
        # Only candidates that would add a material share need the (costly) test.
        material = np.flatnonzero(gain_r2 >= MIN_EXPLAINED_INCREASE)
        if material.shape[0] == 0:
            break
        chosen_rows = [remaining_idx[int(j)] for j in material]
        p = np.min(
            [
                screen(sc.r, base, sc.z_rows[chosen_rows], sc.order).p
                for sc, base in zip(scales, bases, strict=True)
            ],
            axis=0,
        ) * len(scales)
        passed = p <= levels[chosen_rows]
        if first is not None:
            leading = first[chosen_rows]
            if np.any(passed & leading):
                passed &= leading
        if not np.any(passed):
            break
        pick = int(material[int(np.argmax(np.where(passed, gain_r2[material], -np.inf)))])
        chosen = remaining_idx.pop(pick)
        selected.append(chosen)
        holm_levels.append(float(levels[chosen]))
        bases = [
            np.column_stack([base, sc.z_rows[chosen]])
            for sc, base in zip(scales, bases, strict=True)
        ]
    return selected, holm_levels, bases


def _joint_model(
    r: FloatArray,
    r_g: FloatArray,
    kept: list[_Series],
    selected: list[int],
    holm_levels: list[float],
    base: FloatArray,
    order: int,
    alpha: float,
) -> tuple[list[CandidateFinding], float, FloatArray, FloatArray]:
    """The selected candidates fitted jointly: findings, explained share, what is left."""
    findings: list[CandidateFinding] = []
    joint_r2_full: list[float] = []
    full_cols: list[FloatArray] = []
    for idx in selected:
        full_cols.append(kept[idx].full)
        joint_r2_full.append(_full_rate_r2(r, full_cols))
    explained = joint_r2_full[-1] if joint_r2_full else 0.0
    remaining_full = r.copy()
    remaining_grid = r_g.copy()
    if not selected:
        return findings, explained, remaining_full, remaining_grid
    # Intervals of selected candidates use the noise model of the final joint model.
    test = hac_fit(r_g, base, order)
    test_se = np.sqrt(np.maximum(np.diag(test.cov), 0.0))
    joint = ar_model_fit(r_g, base, order)
    se = np.sqrt(np.maximum(np.diag(joint.cov), 0.0))
    for pos, idx in enumerate(selected):
        s = kept[idx]
        b_std = float(joint.beta[pos + 1])
        se_std = float(se[pos + 1])
        coef = b_std / s.std
        df = int(joint.df[pos + 1])
        p = _p_value(float(test.beta[pos + 1]), float(test_se[pos + 1]), int(test.df[pos + 1]))
        interval = _interval(coef, se_std / s.std, df, alpha)
        remaining_full -= coef * (s.full - s.mean)
        remaining_grid -= coef * (s.grid - s.mean)
        findings.append(
            CandidateFinding(
                name=s.name,
                kind=s.kind,
                explained_fraction=_full_rate_r2(r, [s.full]),
                joint_explained_fraction=joint_r2_full[pos],
                coefficient=coef * s.unit,
                interval=_scaled(interval, s.unit),
                p_value=p,
                significant=p <= holm_levels[pos] and _excludes_zero(interval),
                selected=True,
                rank=0,
            )
        )
    return findings, explained, remaining_full, remaining_grid


def _alone_findings(
    r: FloatArray,
    kept: list[_Series],
    selected: list[int],
    alone: Screen | None,
    sizes: Screen | None,
    alpha: float,
    weights: FloatArray,
) -> list[CandidateFinding]:
    """Each candidate not selected, tested alone with an intercept (weighted Bonferroni over
    all, with the weights of the selection) and sized by least squares."""
    if alone is None or sizes is None:
        return []
    findings = []
    for j, s in enumerate(kept):
        if j in selected:
            continue
        coef = float(sizes.beta[j]) / s.std
        p = float(alone.p[j])
        interval = _interval(coef, float(sizes.se[j]) / s.std, int(sizes.df[j]), alpha)
        findings.append(
            CandidateFinding(
                name=s.name,
                kind=s.kind,
                explained_fraction=_full_rate_r2(r, [s.full]),
                joint_explained_fraction=None,
                coefficient=coef * s.unit,
                interval=_scaled(interval, s.unit),
                p_value=p,
                significant=p <= alpha * float(weights[j]) / float(np.sum(weights))
                and _excludes_zero(interval),
                selected=False,
                rank=0,
            )
        )
    return findings


def _timing_significant(ordered: Sequence[CandidateFinding], lag: int, dt: float) -> bool:
    """Timing counts only when the delay survived the forward selection, with the sign of the
    searched lag and a size of at least half a sample: the lag search maximises the fit over
    many lags, so an unadjusted test of the lag it picked would see delays in pure noise."""
    lag_finding = next((f for f in ordered if f.kind == "lag"), None)
    if lag_finding is None or lag == 0:
        return False
    return (
        lag_finding.selected
        and lag_finding.significant
        and (lag_finding.coefficient > 0) == (lag < 0)
        and abs(lag_finding.coefficient) >= dt / 2.0
    )


def _rank(findings: Sequence[CandidateFinding]) -> list[CandidateFinding]:
    """Selected findings in order of entry, then the rest by explained fraction.

    A significant offset is not part of the forward selection; it goes before the first
    selected candidate that it out-explains.
    """
    chosen = [f for f in findings if f.selected and f.kind != "offset"]
    rest = sorted((f for f in findings if not f.selected), key=lambda f: -f.explained_fraction)
    for f in findings:
        if f.selected and f.kind == "offset":
            at = next(
                (i for i, c in enumerate(chosen) if f.explained_fraction > c.explained_fraction),
                len(chosen),
            )
            chosen.insert(at, f)
    return [replace(f, rank=i + 1) for i, f in enumerate([*chosen, *rest])]


def _delay_slope(sim: FloatArray, lag: int, dt: float) -> FloatArray:
    """The series whose coefficient is the delay d of the simulation, in seconds.

    If sim(t) = ref(t − d) then r(t) = sim(t + d) − sim(t) = d · [sim(t + d) − sim(t)] / d, so
    the secant slope over the lag found by the search (d = −lag·dt) explains a pure delay
    exactly with coefficient d; without a lag it is the derivative, the first-order term of
    the same expansion. Samples whose shifted partner falls outside the record repeat the edge
    value; the diagnosis only fits the samples where it exists.
    """
    if lag == 0:
        return np.asarray(np.gradient(sim, dt), dtype=np.float64)
    n = sim.shape[0]
    ahead = sim[np.clip(np.arange(n) - lag, 0, n - 1)]
    return np.asarray((ahead - sim) / (-lag * dt), dtype=np.float64)


def _scaled(interval: tuple[float, float], unit: float) -> tuple[float, float]:
    return (interval[0] * unit, interval[1] * unit)


def _pow2_scale(magnitude: float) -> float:
    """The power of two that brings ``magnitude`` into [0.5, 1); 1 for zero."""
    if magnitude <= 0.0 or not math.isfinite(magnitude):
        return 1.0
    return math.ldexp(1.0, -math.frexp(magnitude)[1])


def _varies(x: FloatArray) -> bool:
    return float(np.ptp(x)) > 1e-12 * max(float(np.max(np.abs(x))), 1e-300)


def _free_name(name: str, taken: set[str]) -> str:
    return name if name not in taken else f"{name} (automatic)"


def _p_value(beta: float, se: float, df: int) -> float:
    if se <= 0.0 or not math.isfinite(se):
        return 0.0 if beta != 0.0 and se == 0.0 else 1.0
    from scipy import stats

    return float(2.0 * stats.t.sf(abs(beta) / se, df))


def _is_minor(e: Effect) -> bool:
    return e.significant and not e.relevant and not e.stands_in_for


# -- causes, responses and effects ----------------------------------------------------------------


def _split_responses(
    ref: FloatArray,
    sim: FloatArray,
    dt: float,
    user: _UserSeries,
    declared_responses: Collection[str],
    declared_causes: Collection[str],
    exogenous: Collection[str] = (),
) -> tuple[_UserSeries, tuple[Response, ...]]:
    """The user's candidates that may be causes, and those set apart as responses.

    A channel x is set apart when the spec says so (``declared``), or when it is

    * an **echo** of the scored signal: on block means of :data:`SLOW_SCALE_S`, the measured
      signal explains at least :data:`ECHO_MIN_R2` of x's variance (an instrument of it, its
      derivative: the bus voltage, the state of charge's rate for a battery power) or
      :data:`ECHO_INCREMENT_MIN_R2` of the variance of x's increments (its integral: the
      state of charge), and the simulated signal at least :data:`ECHO_SIMULATED_RATIO` of
      that; or the measured signal explains at least :data:`ECHO_WHOLE_MIN_R2` of x and at
      least :data:`ECHO_WHOLE_RATIO` of what its simulated part and the residual explain
      with coefficients of their own, and the simulated signal at least
      :data:`RESPONSE_MIN_R2` (x responds to the measured signal as a whole; one that leads it
      acts on it and is ``reproduced``). Echoes are never causes, whatever moves them;
    * a **consequence** of what the model reproduces (``follows``), unless it is exogenous:
      on the same block means, (1) the simulated signal explains at least
      :data:`RESPONSE_MIN_R2` of its variance, (2) the residual adds less than
      :data:`RESPONSE_RESIDUAL_RATIO` + var(r) / var(sim) of that on top (what a response to
      the whole measured signal gets from r), and (3) x does not lead the measured signal by
      :data:`RESPONSE_MIN_LEAD_S` or more; a channel that meets (1) and (2) but leads (a
      pedal position) is a cause the model already reproduces through its inputs
      (``reproduced``), no effect it lacks.

    The consequence test asks the simulated signal, not the measured one: a missing load is
    part of the measured signal, so the measured signal always "explains" it, while a response
    to what the model reproduces moves with the simulation and a missing load moves with the
    residual only. No running sum enters either test: two slowly trending series correlate
    whatever their causes. The spec's causes are never set apart.
    """
    kept: _UserSeries = []
    echoes: list[Response] = []
    residual = ref - sim
    lead_window = max(1, round(RESPONSE_LEAD_WINDOW_S / dt))
    sim_varies = _varies(sim)
    slow = max(1, round(SLOW_SCALE_S / dt))
    if ref.shape[0] // slow < MIN_SLOW_BLOCKS:
        slow = 1
    ref_s, sim_s = block_means(ref, slow), block_means(sim, slow)
    r_s = ref_s - sim_s
    residual_ratio = float(np.var(r_s)) / max(float(np.var(sim_s)), 1e-300)
    for name, kind, values in user:
        if kind in ("lag", "gain") or name in declared_causes or not _varies(values):
            kept.append((name, kind, values))
            continue
        explains = _full_rate_r2(residual, [values])
        if name in declared_responses:
            echoes.append(Response(name, kind, "declared", 0.0, 0.0, 0.0, explains))
            continue
        x_s = block_means(values, slow)
        whole = _full_rate_r2(x_s, [ref_s])
        instrument = max(
            _echo_share(x_s, ref_s, sim_s),
            _echo_share(np.diff(x_s), ref_s[1:], sim_s[1:], ECHO_INCREMENT_MIN_R2),
        )
        # A response moves with the simulated part too; a missing load that makes most of
        # the measured signal's slow variation does not.
        parts = _full_rate_r2(x_s, [sim_s, r_s])
        responds = (
            whole >= ECHO_WHOLE_MIN_R2
            and whole >= ECHO_WHOLE_RATIO * parts
            and _full_rate_r2(x_s, [sim_s]) >= RESPONSE_MIN_R2
        )
        if instrument > 0.0 or responds:
            # One that leads the measured signal acts on it (a pedal): it is no echo, but
            # what it does the measured signal holds whole, and the model reproduces through
            # its inputs.
            # A derivative's lead is its smoothing window's, not the channel's.
            acts = instrument == 0.0 and kind != "derivative"
            lead = _lead(ref, values, lead_window) if acts else 0
            reason = "reproduced" if lead * dt >= RESPONSE_MIN_LEAD_S - 0.5 * dt else "echo"
            echoes.append(
                Response(name, kind, reason, max(instrument, whole), 0.0, lead * dt, explains)
            )
            continue
        if name in exogenous or not sim_varies:
            kept.append((name, kind, values))
            continue
        # On the slow scale, as the echo test: a quantised channel (a state of charge shown in
        # whole percent) or its rate is resolved only there.
        by_sim = _full_rate_r2(x_s, [sim_s])
        added = _full_rate_r2(x_s, [sim_s, r_s]) - by_sim
        allowed = RESPONSE_RESIDUAL_RATIO + residual_ratio
        lead = _lead(ref, values, lead_window)
        if by_sim >= RESPONSE_MIN_R2 and added < allowed * by_sim:
            # Ahead of the measured signal it acts on it (a pedal); the simulation reproduces
            # it through the model's inputs all the same, so it is no effect the model lacks.
            reason = "follows" if lead * dt < RESPONSE_MIN_LEAD_S - 0.5 * dt else "reproduced"
            echoes.append(
                Response(name, kind, reason, by_sim, max(added, 0.0), lead * dt, explains)
            )
        else:
            kept.append((name, kind, values))
    return kept, tuple(echoes)


def _lead(ref: FloatArray, values: FloatArray, window: int) -> int:
    """Samples by which ``values`` leads the measured signal at the peak of their
    |cross-correlation| within ±``window``. Taken against the measured signal: the simulation
    is driven by logged inputs (a speed) that themselves follow the driver, so its timing says
    nothing of which way a channel acts."""
    if not _varies(ref):
        return 0
    # The direction of the peak |correlation|: a voltage falls as the power rises.
    sign = 1.0 if dot(values - float(np.mean(values)), ref - float(np.mean(ref))) >= 0 else -1.0
    return search_lag(ref, sign * values, window).lag


def _echo_share(
    x: FloatArray, ref: FloatArray, sim: FloatArray, floor: float = ECHO_MIN_R2
) -> float:
    """The share of x's variance the measured signal explains when x is an echo of it (at
    least ``floor``, and the simulated signal explains at least :data:`ECHO_SIMULATED_RATIO`
    of that), else 0."""
    if x.shape[0] < 3 or not _varies(x):
        return 0.0
    by_ref = _full_rate_r2(x, [ref])
    if by_ref < floor or _full_rate_r2(x, [sim]) < ECHO_SIMULATED_RATIO * by_ref:
        return 0.0
    return by_ref


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


def _least_squares_fit(r: FloatArray, columns: Sequence[FloatArray]) -> FloatArray:
    """The least-squares combination of ``columns`` closest to r (no intercept of its own)."""
    design = np.column_stack(columns)
    gram = np.einsum("ti,tj->ij", design, design)
    coef = np.linalg.pinv(gram, rcond=RCOND) @ np.einsum("ti,t->i", design, r)
    return np.asarray(design @ coef, dtype=np.float64)


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
