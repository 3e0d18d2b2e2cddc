"""What a residual diagnosis finds, as typed, immutable values: the candidate series that go in
(:class:`Candidate`) and the :class:`Diagnosis` that comes out, with its candidate findings,
effects, responses and localisation.

The types are the diagnosis's contract with the layers above (results, scoring and report):
they hold numbers and names only, no wording."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy.typing as npt

from ..stats import Whiteness
from .thresholds import MIN_SHARE

CandidateKind = Literal["declared", "channel", "derivative", "lag", "gain", "offset"]
NoteKind = Literal["constant_simulation", "decimated", "constant", "duplicate", "collinear"]


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
    """Where in time the residual concentrates (:func:`pytest_hevval.core.groups.concentration`).

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
class Note:
    """Something the diagnosis dropped or changed, and why: what happened and the names and
    numbers it concerns, for the report to word
    (:func:`pytest_hevval.report.diagnosis_text.note_text`).

    Attributes
    ----------
    kind:
        ``"constant_simulation"``: the simulated signal is constant, so gain and lag cannot be
        estimated. ``"decimated"``: the regressions use block means of ``samples`` samples
        (``seconds`` long). What became of ``candidate``: ``"constant"``, ``"duplicate"`` (of
        ``other``) or ``"collinear"`` (a linear combination of the candidates before it), each
        dropped.
    """

    kind: NoteKind
    candidate: str = ""
    other: str = ""
    samples: int = 0
    seconds: float = 0.0


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
    notes: tuple[Note, ...] = ()
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


def _is_minor(e: Effect) -> bool:
    return e.significant and not e.relevant and not e.stands_in_for
