"""What a fix does before the model is touched: the series an effect's fix adds to the simulated
output, the signals above that the model integrates from the diagnosed one (an energy of its
power) and their λ with each fix integrated the same way, and ``hevval diagnose --try``, which
scores the signal (and those above it) again with a term added."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..core.characteristics import SignalCharacteristics, signal_characteristics
from ..core.registry import FUSED_CHARACTERISTICS
from ..core.residual import PREDICTED_CHARACTERISTICS, Candidate, Diagnosis, Effect
from ..errors import DataError, ExpressionError, SpecError
from ..results.signal_diagnosis import SignalAbove
from ..spec.expressions import parse_signal
from .candidates import _full_reference, _on_grid
from .engine import Evaluation

__all__ = [
    "INTEGRAL_TOLERANCE",
    "TriedAbove",
    "TriedTerm",
    "fix_series",
    "integrals_above",
    "running_integral",
    "term_values",
    "try_term",
]

FloatArray = npt.NDArray[np.float64]


#: A signal counts as the running integral of the one below it when a · ∫ below dt + b
#: reproduces its simulated output within this fraction of its range at every scored sample
#: (an energy the model integrates from its power matches to rounding; an unrelated parent
#: misses by tens of per cent).
INTEGRAL_TOLERANCE = 1e-3


def _cumulative(values: FloatArray, time: FloatArray) -> FloatArray:
    """The running trapezoid integral of ``values`` over ``time``, from 0."""
    steps = 0.5 * (values[1:] + values[:-1]) * np.diff(time)
    return np.concatenate(([0.0], np.cumsum(steps)))


def running_integral(upper: FloatArray, lower: FloatArray, time: FloatArray) -> float | None:
    """The factor a when ``upper`` ≈ a · (running trapezoid integral of ``lower`` over
    ``time``) + b within :data:`INTEGRAL_TOLERANCE` of ``upper``'s range at every sample, else
    None (also for series that are constant, not finite or of unequal length)."""
    upper = np.asarray(upper, dtype=np.float64)
    lower = np.asarray(lower, dtype=np.float64)
    if not (upper.shape == lower.shape == time.shape and upper.shape[0] >= 3):
        return None
    if not (np.all(np.isfinite(upper)) and np.all(np.isfinite(lower))):
        return None
    integral = _cumulative(lower, time)
    spread = float(np.ptp(upper))
    if spread <= 0.0 or np.ptp(integral) <= 0.0:
        return None
    design = np.column_stack([integral, np.ones_like(integral)])
    fitted, *_ = np.linalg.lstsq(design, upper, rcond=None)
    misfit = float(np.max(np.abs(upper - design @ fitted)))
    return float(fitted[0]) if misfit <= INTEGRAL_TOLERANCE * spread else None


def _scored_time(evaluation: Evaluation) -> FloatArray:
    """The grid times of the scored samples (those outside gaps)."""
    aligned = evaluation.aligned
    assert aligned is not None
    return aligned.time if aligned.gap_mask is None else aligned.time[~aligned.gap_mask]


def integrals_above(
    evaluation: Evaluation, path: str
) -> tuple[tuple[tuple[str, float], ...], str | None]:
    """The signals above ``path``, nearest first, as far up as each one's simulated output is
    the running integral of the one below it (:func:`running_integral`), with its factor; and
    why the walk stopped short of the top, None when it did not. None is followed across a gap
    inside the scored samples (``nan: omit``): the model integrates what happens in the gap,
    which the scored samples do not hold."""
    names = {"/".join(n): n for _, n, _ in evaluation.spec.walk()}
    time = _scored_time(evaluation)
    mask = evaluation.aligned.gap_mask if evaluation.aligned is not None else None
    gapped = mask is not None and bool(np.any(np.diff(np.flatnonzero(~mask)) > 1))
    chain: list[tuple[str, float]] = []
    lower = path
    while len(names.get(lower, ())) > 1:
        upper = "/".join(names[lower][:-1])
        upper_name, lower_name = names[upper][-1], names[lower][-1]
        if upper not in evaluation.arrays or lower not in evaluation.arrays:
            return tuple(chain), f"{upper_name} or {lower_name} was not kept"
        if gapped:
            # The model integrates through a gap; the scored samples cannot follow it there.
            return tuple(chain), (
                f"a gap inside the scored samples interrupts the running integral of "
                f"{lower_name}, so {upper_name} cannot be followed through it"
            )
        factor = running_integral(evaluation.arrays[upper][1], evaluation.arrays[lower][1], time)
        if factor is None:
            return tuple(chain), (
                f"{upper_name} is not the running integral of {lower_name} in this model"
            )
        chain.append((upper, factor))
        lower = upper
    return tuple(chain), None


def _integrated(
    chain: Sequence[tuple[str, float]], added: FloatArray, time: FloatArray
) -> Iterator[tuple[str, FloatArray]]:
    """What ``added`` to the lower signal adds to each signal of ``chain`` above it."""
    for upper, factor in chain:
        added = factor * _cumulative(added, time)
        yield upper, added


def _scorer(evaluation: Evaluation, path: str) -> Callable[[FloatArray], SignalCharacteristics]:
    """The signal's characteristics for a simulated output, as the spec scores it (its lag
    search, correlation form and declared range)."""
    spec = evaluation.spec
    aligned = evaluation.aligned
    assert aligned is not None
    node = next(n for _, names, n in spec.walk() if "/".join(names) == path)
    reference = evaluation.arrays[path][0]

    def scored(simulated: FloatArray) -> SignalCharacteristics:
        return signal_characteristics(
            reference,
            np.asarray(simulated, dtype=np.float64),
            dt=aligned.grid.dt,
            max_lag_s=spec.alignment.max_lag_s,
            correlation=spec.correlation,
            reference_range=node.reference_range,
        )

    return scored


def _predicted_lambdas(found: SignalCharacteristics) -> dict[str, float]:
    """λ3 and λ4 of a scored signal, by name, as the diagnosis predicts them."""
    return {
        name: float(value)
        for name, value in zip(FUSED_CHARACTERISTICS, found.lambdas, strict=False)
        if name in PREDICTED_CHARACTERISTICS
    }


def fix_series(
    effect: Effect, simulated: FloatArray, candidates: Mapping[str, Candidate]
) -> FloatArray | None:
    """What an effect's fix adds to the signal's simulated output at each scored sample:
    ``fix_coefficient`` × its candidate (the simulated output itself for a gain) plus
    ``fix_constant``; None for a lag (a delay adds no series) or a candidate not at hand."""
    if effect.kind == "offset":
        return np.full(simulated.shape, effect.fix_constant, dtype=np.float64)
    if effect.kind == "lag":
        return None
    if effect.kind == "gain":
        base = np.asarray(simulated, dtype=np.float64)
    elif (candidate := candidates.get(effect.name)) is not None:
        base = np.asarray(candidate.values, dtype=np.float64)
    else:
        return None
    return effect.fix_coefficient * base + effect.fix_constant


def _predicted_above(
    evaluation: Evaluation,
    path: str,
    chain: Sequence[tuple[str, float]],
    diagnosis: Diagnosis,
    candidates: Sequence[Candidate],
) -> tuple[SignalAbove, ...]:
    """Each signal of ``chain`` scored as the spec scores it, now and with each finding's fix
    integrated into it as the model integrates the signal below."""
    if not chain:
        return ()
    time = _scored_time(evaluation)
    simulated = np.asarray(evaluation.arrays[path][1], dtype=np.float64)
    by_name = {c.name: c for c in candidates}
    scorers = {upper: _scorer(evaluation, upper) for upper, _ in chain}
    uppers = {u: np.asarray(evaluation.arrays[u][1], dtype=np.float64) for u, _ in chain}
    predicted: dict[str, dict[str, dict[str, float]]] = {upper: {} for upper, _ in chain}
    for effect in diagnosis.effects:
        series = fix_series(effect, simulated, by_name) if effect.relevant else None
        if series is None:
            continue
        for upper, added in _integrated(chain, series, time):
            found = scorers[upper](uppers[upper] + added)
            predicted[upper][effect.name] = _predicted_lambdas(found)
    units = {s.path: s.unit for s in evaluation.result.signals}
    return tuple(
        SignalAbove(
            signal=upper,
            unit=units.get(upper),
            per_second=factor,
            lambdas=_predicted_lambdas(scorers[upper](uppers[upper])),
            predicted=predicted[upper],
        )
        for upper, factor in chain
    )


@dataclass(frozen=True)
class TriedAbove:
    """A signal above the tried one, the running integral of the one below it in the model,
    scored again with the term integrated into it."""

    signal: str
    unit: str | None
    before: SignalCharacteristics
    after: SignalCharacteristics


@dataclass(frozen=True)
class TriedTerm:
    """A term added to a signal's simulated output and the signal scored again through the
    spec (``hevval diagnose --try``): what a fix would do before the model is touched.
    ``above`` are the signals above it that the model integrates from it, scored again with
    the term integrated; ``above_note`` says why the signals further up are not."""

    signal: str
    term: str
    unit: str | None
    before: SignalCharacteristics
    after: SignalCharacteristics
    above: tuple[TriedAbove, ...] = ()
    above_note: str | None = None


def try_term(evaluation: Evaluation, path: str, term: str) -> TriedTerm:
    """Score ``path`` with ``term`` added to its simulated output, as the spec scores it (its
    lag search, correlation form and declared range).

    ``term`` is an expression over the reference's columns and the spec's declared candidates
    (by name), e.g. ``1.12 * heating_aircon_kw - 1.47``: the fix the diagnosis prints. A signal
    above whose simulated output is the running integral of the one below it
    (:func:`integrals_above`: an energy of this power) is scored again too, with the term
    integrated the same way; the signals below and the rest are not changed."""
    spec = evaluation.spec
    aligned = evaluation.aligned
    if aligned is None or path not in evaluation.arrays:
        known = ", ".join(repr(p) for p in evaluation.arrays) or "none kept"
        raise DataError(
            f"no signal {path!r} in this spec (signals: {known})",
            file=str(spec.path),
            hint="pass --signal with a path such as E_batt/P_batt",
        )
    node = next(n for _, names, n in spec.walk() if "/".join(names) == path)
    values = term_values(evaluation, term)
    if aligned.gap_mask is not None:
        values = values[~aligned.gap_mask]
    if not np.all(np.isfinite(values)):
        raise SpecError(
            f"--try {term!r} is not finite at {int(np.count_nonzero(~np.isfinite(values)))} "
            "scored samples",
            file=str(spec.path),
            hint="check the columns it reads for gaps, or guard them in the expression",
        )
    chain, note = integrals_above(evaluation, path)
    units = {s.path: s.unit for s in evaluation.result.signals}
    (before, after), *rescored = (
        _before_after(evaluation, signal, added)
        for signal, added in [(path, values), *_integrated(chain, values, _scored_time(evaluation))]
    )
    return TriedTerm(
        signal=path,
        term=term,
        unit=node.unit,
        before=before,
        after=after,
        above=tuple(
            TriedAbove(signal=upper, unit=units.get(upper), before=b, after=a)
            for (upper, _), (b, a) in zip(chain, rescored, strict=True)
        ),
        above_note=note,
    )


def term_values(evaluation: Evaluation, term: str) -> FloatArray:
    """``term`` (an expression over the reference's columns and the spec's declared
    candidates, by name: a fix the diagnosis prints) on the whole aligned grid, gaps included,
    its columns taken as the diagnosis takes them; a :class:`SpecError` naming the term when it
    cannot be evaluated."""
    spec = evaluation.spec
    aligned = evaluation.aligned
    assert aligned is not None
    try:
        expression = parse_signal(term)
        if expression.is_column and expression.columns[0] not in spec.candidates:
            # A bare number or name: a number is a constant, a name a column or candidate.
            expression = parse_signal(f"({term})")
        record = _full_reference(evaluation)
        columns: dict[str, FloatArray] = {}
        for name in expression.columns:
            if name in spec.candidates:
                declared = spec.candidates[name]
                columns[name] = declared.evaluate(
                    aligned.columns("reference", declared.columns, "linear"), aligned.time
                )
            elif name in record.channels and (logged := _on_grid(record, name, aligned.time)):
                columns[name] = logged[0]
        values = np.asarray(expression.evaluate(columns, aligned.time), dtype=np.float64)
    except (ExpressionError, DataError) as exc:
        raise SpecError(
            f"--try {term!r}: {exc}",
            file=str(spec.path),
            hint="write the term over the reference's columns (`Heating Power CAN [kW]`) and "
            f"the spec's candidates ({', '.join(spec.candidates) or 'none declared'}), e.g. "
            "--try '1.2 * heating_kw - 2.9'",
        ) from exc
    return values


def _before_after(
    evaluation: Evaluation, path: str, added: FloatArray
) -> tuple[SignalCharacteristics, SignalCharacteristics]:
    """A signal as the spec scores it, and with ``added`` to its simulated output."""
    scored = _scorer(evaluation, path)
    simulated = np.asarray(evaluation.arrays[path][1], dtype=np.float64)
    return scored(simulated), scored(simulated + added)
