"""Residual diagnosis of a scored spec: from an evaluation to candidate effects and back.

The maths lives in :mod:`pytest_hevval.core.residual`; this module gathers the candidates —
the spec's declared ``candidates:`` expressions, every measured reference channel the spec
does not use, and the time derivative of each — on the aligned grid, and diagnoses a signal
(or the level below it, when that one names the cause).
"""

from __future__ import annotations

import ast
import contextlib
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from ..core.characteristics import SignalCharacteristics, signal_characteristics
from ..core.registry import FUSED_CHARACTERISTICS
from ..core.residual import (
    GENERIC_KINDS,
    MIN_SHARE,
    PREDICTED_CHARACTERISTICS,
    Candidate,
    Diagnosis,
    Effect,
    diagnose_residual,
)
from ..data.record import Record
from ..errors import DataError, ExpressionError, HevvalError, SpecError
from ..results.diagnosis import SignalAbove, SignalDiagnosis, candidate_unit
from ..results.spec_result import SignalResult
from ..spec.expressions import Expression, parse_signal
from .engine import DataCache, Evaluation, per_item, scoring_threads

__all__ = [
    "INTEGRAL_TOLERANCE",
    "TriedAbove",
    "TriedTerm",
    "candidates_for",
    "derivative_name",
    "diagnose_failures",
    "diagnose_origin",
    "diagnose_pair",
    "diagnose_signal",
    "diagnosis_target",
    "fix_series",
    "integrals_above",
    "running_integral",
    "term_values",
    "try_term",
]

FloatArray = npt.NDArray[np.float64]

#: Channels beyond this many are not tried automatically (the spec's own come first).
MAX_CHANNELS = 50
#: Window of the centred mean applied to a channel before its derivative is taken.
DERIVATIVE_SMOOTHING_S = 1.0
#: A channel that changes less often than once per smoothing window is quantised (a state of
#: charge in 0.1 % steps, a limit that moves a few times a trip): its mean is taken over this
#: many of its steps before it is differentiated, so that its rate is a slope, not a row of
#: spikes ...
QUANTISED_SMOOTHING_STEPS = 5
#: ... and one that changes fewer times than this over the record has no derivative candidate:
#: a handful of steps says nothing of a rate.
MIN_DERIVATIVE_STEPS = 20
#: Quantities the vehicle cannot move, by the words of a channel's name: never called a
#: consequence of the scored signal (two slowly trending series correlate whatever their
#: causes). The model's inputs are treated alike; the spec can name more under ``causes:``.
EXOGENOUS = re.compile(
    r"(?i)\b(ambient|outside|outdoor|elevation|altitude|latitude|longitude|gps|time|date)\b"
)


def _smoothed(values: FloatArray, window: int) -> FloatArray:
    if window <= 1:
        return values
    from scipy.ndimage import uniform_filter1d

    return np.asarray(uniform_filter1d(values, size=window, mode="nearest"), dtype=np.float64)


def _full_reference(evaluation: Evaluation) -> Record:
    """Every numeric channel of the reference file, read through the spec's data cache (once,
    and let go with the file's other data: :meth:`DataCache.read_whole`)."""
    spec = evaluation.spec
    assert evaluation.aligned is not None
    if spec.reference.kind == "file" and spec.reference.path:
        cache = evaluation.cache or DataCache()
        # If the whole file cannot be read, diagnose with the channels already read.
        with contextlib.suppress(DataError):
            return cache.read_whole(spec.reference)
    return evaluation.aligned.reference


def candidates_for(evaluation: Evaluation, *, channels: bool = True) -> list[Candidate]:
    """Declared expressions, then unused channels and their derivatives, on the grid."""
    spec = evaluation.spec
    aligned = evaluation.aligned
    if aligned is None:
        return []
    time = aligned.time
    keep = None if aligned.gap_mask is None else ~aligned.gap_mask
    found: list[Candidate] = []

    def add(name: str, kind: str, values: FloatArray) -> None:
        # Scored arrays drop the grid points in gaps; candidates must drop the same ones.
        if keep is not None:
            values = values[keep]
        if np.all(np.isfinite(values)) and np.ptp(values) > 0:
            found.append(Candidate(name, kind, values))  # type: ignore[arg-type]

    for name, expression in spec.candidates.items():
        columns = aligned.columns("reference", expression.columns, "linear")
        try:
            add(name, "declared", np.asarray(expression.evaluate(columns, time), dtype=float))
        except HevvalError:
            continue
    if not channels:
        return found
    used: set[str] = set()
    for _, _, node in spec.walk():
        used.update(node.ref.columns)
        if node.ref.is_column:
            used.add(node.ref.source)
    record = _full_reference(evaluation)
    # Logged channels are quantised (GPS elevation in centimetre steps) or held between CAN
    # frames; differentiated sample by sample they are mostly steps. A centred 1 s mean first
    # keeps the slow slope the model may lack; a coarser channel is averaged over several of
    # its steps (derivative_window).
    smoothing = max(1, round(DERIVATIVE_SMOOTHING_S / aligned.grid.dt))
    time_name = spec.reference.options.time
    names = [
        n
        for n in (record.numeric or tuple(record.channels))
        if n not in used and n != time_name and n in record.channels
    ][:MAX_CHANNELS]
    for name in names:
        found_on_grid = _on_grid(record, name, time)
        if found_on_grid is None:
            continue
        on_grid, values = found_on_grid
        add(name, "channel", on_grid)
        window = derivative_window(values, smoothing, on_grid.shape[0])
        if window is not None:
            add(derivative_name(name), "derivative", np.gradient(_smoothed(on_grid, window), time))
    return found


def _on_grid(record: Record, name: str, time: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """A logged channel linearly on the grid, and its finite logged values; None when it
    holds fewer than three finite values."""
    channel = record.channels[name]
    values = np.asarray(channel.values, dtype=np.float64)
    ok = np.isfinite(values)
    if ok.sum() < 3:
        return None
    return np.interp(time, channel.time[ok], values[ok]), values[ok]


def derivative_window(values: FloatArray, smoothing: int, samples: int) -> int | None:
    """The centred mean's window (grid samples) before a channel is differentiated: the
    default ``smoothing``, or :data:`QUANTISED_SMOOTHING_STEPS` of its steps for a channel
    that changes less often than once per window; None (no derivative) for one that changes
    fewer than :data:`MIN_DERIVATIVE_STEPS` times."""
    steps = int(np.count_nonzero(np.diff(values)))
    if steps < MIN_DERIVATIVE_STEPS:
        return None
    spacing = samples / steps
    if spacing <= smoothing:
        return smoothing
    return min(samples, round(QUANTISED_SMOOTHING_STEPS * spacing))


def declared_unit(expression: Expression) -> str | None:
    """The unit of a declared candidate, read from the columns it uses: one column's, a sum or
    difference of columns in one unit, scaled by a number, or the derivative (``per s``) of
    one; None when the expression combines units otherwise (its unit is then unknown)."""
    if expression.is_column:
        return candidate_unit(expression.columns[0], "channel")
    # The parsed form the expression keeps: its tree and the columns behind its names.
    tree = expression._tree
    names = expression._names
    return None if tree is None else _unit_of(tree, names)


def _unit_of(node: ast.expr, names: Mapping[str, str]) -> str | None:
    if isinstance(node, ast.Name):
        column = names.get(node.id)
        return None if column is None else candidate_unit(column, "channel")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        return _unit_of(node.operand, names)
    if isinstance(node, ast.BinOp):
        if isinstance(node.op, (ast.Add, ast.Sub)):
            left, right = _unit_of(node.left, names), _unit_of(node.right, names)
            return left if left is not None and left == right else None
        if isinstance(node.op, (ast.Mult, ast.Div)) and isinstance(node.right, ast.Constant):
            return _unit_of(node.left, names)
        if isinstance(node.op, ast.Mult) and isinstance(node.left, ast.Constant):
            return _unit_of(node.right, names)
        return None
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args:
        inner = _unit_of(node.args[0], names)
        if node.func.id == "smooth":
            return inner
        if node.func.id == "derivative" and inner is not None:
            return f"{inner}/s"
    return None


def _with_derivatives(names: Sequence[str]) -> tuple[str, ...]:
    """Names declared for a channel also cover its derivative candidate."""
    return (*names, *(derivative_name(n) for n in names))


def derivative_name(channel: str) -> str:
    """The name of the derivative candidate of a channel."""
    return f"d/dt {channel}"


def diagnose_pair(
    evaluation: Evaluation,
    reference: FloatArray,
    simulated: FloatArray,
    candidates: Sequence[Candidate],
    unit: str | None = None,
) -> Diagnosis:
    """Diagnose one aligned pair of the evaluation with the spec's diagnosis settings.

    ``unit`` is the scored signal's unit: candidates logged in the same physical dimension (a
    load in kW for a power in kW) are named first among effects the record cannot tell apart.
    """
    assert evaluation.aligned is not None
    spec = evaluation.spec
    settings = spec.diagnosis
    signal_unit = unit or ""
    units = {
        c.name: declared_unit(spec.candidates[c.name])
        if c.kind == "declared" and c.name in spec.candidates
        else candidate_unit(c.name, c.kind)
        for c in candidates
    }
    in_dimension = [
        c.name
        for c in candidates
        if signal_unit
        and (found := units[c.name]) is not None
        and _same_dimension(found, signal_unit)
    ]
    # The gatekeeping order's first family, besides the loads in the signal's dimension: the
    # spec's declared suspects whose unit is unknown (an expression such as a road load) and
    # the spec's causes. A declared candidate in another dimension (a temperature) is tested on
    # what those leave, as any channel is.
    first = [
        *(c.name for c in candidates if c.kind == "declared" and units[c.name] is None),
        *_with_derivatives(settings.causes),
    ]
    inputs = set(spec.model.inputs)
    over_inputs = [
        c.name
        for c in candidates
        if c.kind == "declared"
        and c.name in spec.candidates
        and all(col in inputs for col in spec.candidates[c.name].columns)
    ]
    exogenous = [
        c.name
        for c in candidates
        if c.name in _with_derivatives(spec.model.inputs)
        or EXOGENOUS.search(c.name)
        or (
            c.kind == "declared"
            and c.name in spec.candidates
            and all(EXOGENOUS.search(col) for col in spec.candidates[c.name].columns)
        )
    ]
    return diagnose_residual(
        reference,
        simulated,
        dt=evaluation.aligned.grid.dt,
        candidates=candidates,
        max_lag_s=evaluation.spec.alignment.max_lag_s,
        responses=_with_derivatives(settings.responses),
        # An expression over the model's inputs (a road load from the speed) is a cause.
        causes=[*_with_derivatives(settings.causes), *over_inputs],
        min_share=MIN_SHARE if settings.min_share is None else settings.min_share,
        groups=[members for _, members in settings.groups],
        in_dimension=in_dimension,
        first=first,
        # A channel the model reads is an input: never a consequence (its rate may still be
        # an echo: the state of charge's rate is the battery current).
        exogenous=exogenous,
    )


def diagnose_signal(
    evaluation: Evaluation,
    path: str,
    *,
    channels: bool = True,
    candidates: Sequence[Candidate] | None = None,
) -> SignalDiagnosis:
    """The full diagnosis of one signal (see docs/diagnosis.md); ``candidates`` are
    ``candidates_for(evaluation, channels=channels)`` when given (the same for every signal of
    a spec, so a caller diagnosing several signals finds them once)."""
    if evaluation.aligned is None or path not in evaluation.arrays:
        known = ", ".join(repr(p) for p in evaluation.arrays) or "none kept"
        raise DataError(
            f"no signal {path!r} in this spec (signals: {known})",
            file=str(evaluation.spec.path),
            hint="pass --signal with a path such as E_batt/P_batt",
        )
    reference, simulated = evaluation.arrays[path]
    result = evaluation.result.signal(path)
    if candidates is None:
        candidates = candidates_for(evaluation, channels=channels)
    diagnosis = diagnose_pair(evaluation, reference, simulated, candidates, result.unit)
    by_path = {s.path: s for s in evaluation.result.signals}
    origin_path = result.origins[0] if result.origins else path
    origin = by_path.get(origin_path, result)
    chain, note = integrals_above(evaluation, path)
    return SignalDiagnosis(
        spec=evaluation.result.spec,
        signal=path,
        unit=result.unit,
        passed=result.passed,
        origin=(origin.path, origin.level),
        origins=tuple((p, by_path[p].level) for p in result.origins if p in by_path),
        diagnosis=diagnosis,
        above=_predicted_above(evaluation, path, chain, diagnosis, candidates),
        above_note=note,
    )


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


#: Decimal prefixes that scale a unit without changing what it measures (kW and W).
_SI_PREFIXES = ("k", "M", "G", "m", "µ", "u")


def _same_dimension(unit: str, other: str) -> bool:
    """Whether two unit texts measure the same quantity: the same symbol, up to one decimal
    prefix (``kW`` and ``W``, ``mA`` and ``A``). Deliberately narrow: it only decides which of
    two effects the record cannot tell apart is named first, so a miss costs nothing."""

    def bare(text: str) -> set[str]:
        text = text.strip()
        forms = {text}
        if len(text) > 1 and text[0] in _SI_PREFIXES:
            forms.add(text[1:])
        return forms

    return bool(bare(unit) & bare(other))


def _strongest_finding(found: Diagnosis) -> tuple[float, float]:
    """How well a diagnosis names a cause: the share of its largest relevant effect that is a
    channel, expression or derivative (a gain, offset or lag names no cause), then the largest
    share of the residual one significant candidate explains alone."""
    named = max(
        (e.share for e in found.effects if e.relevant and e.kind not in GENERIC_KINDS),
        default=0.0,
    )
    alone = max(
        (c.explained_fraction for c in found.candidates if c.significant),
        default=0.0,
    )
    return named, alone


def diagnose_origin(evaluation: Evaluation, path: str) -> SignalDiagnosis:
    """Diagnose the signal where an error appears, looking one level down when it emerges.

    When the origin has children (they pass, and the error emerges where they combine), the
    origin's own residual may be a running sum or a product, and the weakest child's residual
    often names the cause more directly: a missing load shows in the power at each instant,
    while in the energy it is a slow drift that any warming temperature can mimic. Both are
    diagnosed and the one that names a cause (a relevant channel, expression or derivative)
    with the larger share is returned, else the one with the stronger significant finding,
    with ``asked`` naming the signal asked about.
    """
    signals = _looked_at(evaluation, path)
    candidates = candidates_for(evaluation) if len(signals) > 1 else None
    return _chosen(path, *[diagnose_signal(evaluation, s, candidates=candidates) for s in signals])


def _looked_at(evaluation: Evaluation, path: str) -> tuple[str, ...]:
    """The signals :func:`diagnose_origin` diagnoses for ``path``: itself, then its weakest
    child when it has children."""
    result = evaluation.result
    node = next((s for s in result.signals if s.path == path), None)
    if node is None or not node.children:
        return (path,)  # an unknown path: diagnose_signal says which paths there are
    weakest = min(
        (result.signal(child) for child in node.children),
        key=lambda s: sum(s.lambdas[name] for name in FUSED_CHARACTERISTICS),
    )
    return (path, weakest.path)


def _chosen(
    path: str, found: SignalDiagnosis, below: SignalDiagnosis | None = None
) -> SignalDiagnosis:
    """Of the diagnoses of ``path`` and of its weakest child, the one :func:`diagnose_origin`
    returns."""
    found = replace(found, asked=path)
    if below is not None and _strongest_finding(below.diagnosis) > _strongest_finding(
        found.diagnosis
    ):
        return replace(below, asked=path)
    return found


def diagnosis_target(signal: SignalResult) -> str:
    """The signal a signal's diagnosis looks at: where its error appears."""
    return signal.origins[0] if signal.origins else signal.path


def diagnose_failures(
    evaluation: Evaluation, mode: str = "failed", workers: int | None = None
) -> dict[str, SignalDiagnosis | HevvalError]:
    """The diagnosis of every failing signal (every signal for ``mode="all"``), once per
    signal where an error appears, keyed by that signal's path; a signal that cannot be
    diagnosed keeps the error that says why.

    The signals (each target and, where it has children, its weakest child: see
    :func:`diagnose_origin`) are diagnosed side by side on the spec's scoring threads
    (``workers``, as the engine counts them), each once: a diagnosis is independent of the
    others, and most of its time is spent in numpy and LAPACK calls that release the GIL.
    """
    if mode == "off" or evaluation.aligned is None:
        return {}
    targets = list(
        dict.fromkeys(
            diagnosis_target(signal)
            for signal in evaluation.result.signals
            if mode != "failed" or not signal.passed
        )
    )
    looked_at = {target: _looked_at(evaluation, target) for target in targets}
    # Each signal once, though it be one target's weakest child and another target itself.
    signals = list(dict.fromkeys(s for paths in looked_at.values() for s in paths))
    # The candidates (and the full reference file they come from) once for every signal; if
    # they cannot be found, each signal's diagnosis says why.
    candidates = None
    if len(signals) > 1:
        with contextlib.suppress(HevvalError):
            candidates = candidates_for(evaluation)

    def one(signal: str) -> SignalDiagnosis | HevvalError:
        try:
            return diagnose_signal(evaluation, signal, candidates=candidates)
        except HevvalError as exc:
            return exc

    diagnosed = dict(zip(signals, per_item(one, signals, scoring_threads(workers)), strict=True))
    found: dict[str, SignalDiagnosis | HevvalError] = {}
    for target, paths in looked_at.items():
        results = [diagnosed[p] for p in paths]
        done = [r for r in results if isinstance(r, SignalDiagnosis)]
        # A target whose own or weakest child's diagnosis fails keeps the first error.
        found[target] = (
            _chosen(target, *done)
            if len(done) == len(results)
            else next(r for r in results if isinstance(r, HevvalError))
        )
    return found


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
