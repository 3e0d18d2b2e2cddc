"""Residual diagnosis of a scored spec: from an evaluation to candidate effects and back.

The maths lives in :mod:`pytest_hevval.core.residual`; the candidates — the spec's declared
``candidates:`` expressions, every measured reference channel the spec does not use, and the
time derivative of each — come from :mod:`.candidates`, and what a fix does to the signals
above from :mod:`.fixes`. This module diagnoses a signal (or the level below it, when that one
names the cause) with the spec's settings, and a spec's failing signals side by side.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ..core.registry import FUSED_CHARACTERISTICS
from ..core.residual import GENERIC_KINDS, MIN_SHARE, Candidate, Diagnosis, diagnose_residual
from ..errors import DataError, HevvalError
from ..results.signal_diagnosis import SignalDiagnosis, candidate_unit
from ..results.spec_result import SignalResult
from .candidates import _with_derivatives, candidates_for, declared_unit
from .engine import Evaluation
from .fixes import _predicted_above, integrals_above
from .threads import per_item, scoring_threads

__all__ = [
    "diagnose_failures",
    "diagnose_origin",
    "diagnose_pair",
    "diagnose_signal",
    "diagnosis_target",
]

FloatArray = npt.NDArray[np.float64]


#: Quantities the vehicle cannot move, by the words of a channel's name: never called a
#: consequence of the scored signal (two slowly trending series correlate whatever their
#: causes). The model's inputs are treated alike; the spec can name more under ``causes:``.
EXOGENOUS = re.compile(
    r"(?i)\b(ambient|outside|outdoor|elevation|altitude|latitude|longitude|gps|time|date)\b"
)


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
