"""Residual diagnosis of a scored spec: from an evaluation to candidate effects and back.

The maths lives in :mod:`pytest_hevval.core.diagnosis`; this module gathers the candidates —
the spec's declared ``candidates:`` expressions, every measured reference channel the spec
does not use, and the time derivative of each — on the aligned grid, and formats findings.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .core.diagnosis import (
    GENERIC_KINDS,
    MIN_SHARE,
    SLOW_SCALE_S,
    Candidate,
    Diagnosis,
    diagnose_residual,
)
from .core.registry import FUSED_CHARACTERISTICS, get_characteristic
from .data.record import Record
from .engine import Evaluation
from .errors import DataError, HevvalError, SpecError

__all__ = [
    "candidates_for",
    "derivative_name",
    "diagnose_main",
    "diagnose_origin",
    "diagnose_pair",
    "diagnose_signal",
    "effect_text",
]

FloatArray = npt.NDArray[np.float64]

#: Channels beyond this many are not tried automatically (the spec's own come first).
MAX_CHANNELS = 50
#: Window of the centred mean applied to a channel before its derivative is taken.
DERIVATIVE_SMOOTHING_S = 1.0


def _smoothed(values: FloatArray, window: int) -> FloatArray:
    if window <= 1:
        return values
    from scipy.ndimage import uniform_filter1d

    return np.asarray(uniform_filter1d(values, size=window, mode="nearest"), dtype=np.float64)


def _full_reference(evaluation: Evaluation) -> Record:
    """Every numeric channel of the reference file (read once more, only for diagnosis)."""
    cached = getattr(evaluation, "_full_reference", None)
    if isinstance(cached, Record):
        return cached
    spec = evaluation.spec
    assert evaluation.aligned is not None
    record = evaluation.aligned.reference
    if spec.reference.kind == "file" and spec.reference.path:
        from .data.readers import read_record

        # If the whole file cannot be read, diagnose with the channels already read.
        with contextlib.suppress(DataError):
            record = read_record(str(spec.reference.path), None, spec.reference.options)
    evaluation._full_reference = record  # type: ignore[attr-defined]
    return record


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
    # keeps the slow slope the model may lack.
    smoothing = max(1, round(DERIVATIVE_SMOOTHING_S / aligned.grid.dt))
    time_name = spec.reference.options.time
    names = [
        n
        for n in (record.numeric or tuple(record.channels))
        if n not in used and n != time_name and n in record.channels
    ][:MAX_CHANNELS]
    for name in names:
        channel = record.channels[name]
        values = np.asarray(channel.values, dtype=np.float64)
        ok = np.isfinite(values)
        if ok.sum() < 3:
            continue
        on_grid = np.interp(time, channel.time[ok], values[ok])
        add(name, "channel", on_grid)
        add(derivative_name(name), "derivative", np.gradient(_smoothed(on_grid, smoothing), time))
    return found


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
    settings = evaluation.spec.diagnosis
    signal_unit = unit or ""
    in_dimension = [
        c.name
        for c in candidates
        if signal_unit
        and (found := _candidate_unit(c.name, c.kind)) is not None
        and _same_dimension(found, signal_unit)
    ]
    return diagnose_residual(
        reference,
        simulated,
        dt=evaluation.aligned.grid.dt,
        candidates=candidates,
        max_lag_s=evaluation.spec.alignment.max_lag_s,
        responses=_with_derivatives(settings.responses),
        # A channel the model reads is an input; the spec can name more causes.
        causes=_with_derivatives((*settings.causes, *evaluation.spec.model.inputs)),
        min_share=MIN_SHARE if settings.min_share is None else settings.min_share,
        groups=[members for _, members in settings.groups],
        in_dimension=in_dimension,
    )


def diagnose_signal(evaluation: Evaluation, path: str, *, channels: bool = True) -> dict[str, Any]:
    """The full diagnosis of one signal as JSON-safe data (see docs/diagnosis.md)."""
    if evaluation.aligned is None or path not in evaluation.arrays:
        known = ", ".join(repr(p) for p in evaluation.arrays) or "none kept"
        raise DataError(
            f"no signal {path!r} in this spec (signals: {known})",
            file=str(evaluation.spec.path),
            hint="pass --signal with a path such as E_batt/P_batt",
        )
    reference, simulated = evaluation.arrays[path]
    result = evaluation.result.signal(path)
    diagnosis = diagnose_pair(
        evaluation,
        reference,
        simulated,
        candidates_for(evaluation, channels=channels),
        result.unit,
    )
    by_path = {s.path: s for s in evaluation.result.signals}
    origin_path = result.origins[0] if result.origins else path
    origin = by_path.get(origin_path, result)
    payload: dict[str, Any] = {
        "spec": evaluation.result.spec,
        "signal": path,
        "unit": result.unit,
        "passed": result.passed,
        "origin": {"path": origin.path, "level": origin.level},
        "origins": [{"path": p, "level": by_path[p].level} for p in result.origins if p in by_path],
    }
    payload.update(diagnosis.as_dict())
    for effect in payload["effects"]:
        effect["text"] = effect_text(effect, path.rsplit("/", 1)[-1], result.unit)
    return payload


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


def _candidate_unit(name: str, kind: str) -> str | None:
    """The unit in a logged column's name (``Heating Power CAN [kW]`` → ``kW``), per second for
    its derivative; None for a declared expression, whose unit the spec does not state."""
    base = name.removeprefix("d/dt ") if kind == "derivative" else name
    match = re.search(r"\[([^\]]+)\]\s*$", base)
    if match is None:
        return None
    return f"{match.group(1)}/s" if kind == "derivative" else match.group(1)


def effect_text(effect: Mapping[str, Any], signal: str, unit: str | None) -> str:
    """One effect in physical units with its interval, e.g. ``+0.94 kW of P_batt per kW of
    Heating Power CAN [kW] [0.82, 1.06]``."""
    coef = float(effect["coefficient"])
    low, high = (float(v) for v in effect["interval"])
    unit_text = f" {unit}" if unit else ""
    kind = str(effect["kind"])
    if kind == "offset":
        return f"offset {coef:+.3g}{unit_text} of {signal} [{low:.3g}, {high:.3g}]"
    if kind == "gain":
        return f"gain error {100 * coef:+.2f} % [{100 * low:.2f}, {100 * high:.2f}]"
    if kind == "lag":
        late = "late" if coef > 0 else "early"
        if coef < 0:
            # The interval of the delay in the direction named.
            low, high = -high, -low
        return f"the simulation is {abs(coef):.3g} s {late} [{low:.3g}, {high:.3g}] s"
    per = _candidate_unit(str(effect["name"]), kind)
    per_text = f"{per} of " if per else "unit of "
    return (
        f"{coef:+.3g}{unit_text} of {signal} per {per_text}{effect['name']} [{low:.3g}, {high:.3g}]"
    )


def _lambda_change(before: Mapping[str, Any], after: Mapping[str, Any]) -> str:
    return ", ".join(
        f"{get_characteristic(name).symbol} {float(before[name]):.4f} → {float(after[name]):.4f}"
        for name in after
        if name in before
    )


def _label(name: str) -> str:
    """A channel's name, quoted when it has surrounding spaces (two logged columns can differ
    only by a trailing space)."""
    return repr(name) if name != name.strip() else name


def _share_text(share: float) -> str:
    return f"{100 * share:.1f} %"


def _describe_effects(found: Mapping[str, Any]) -> list[str]:
    effects = found.get("effects") or []
    unit = f" {found['unit']}" if found.get("unit") else ""
    share = float(found.get("min_share", MIN_SHARE))
    before = found.get("lambdas") or {}
    relevant = [e for e in effects if e["relevant"]]
    stand_ins = [e for e in effects if e.get("stands_in_for")]
    minor = [
        e for e in effects if e["significant"] and not e["relevant"] and not e.get("stands_in_for")
    ]
    lines: list[str] = []
    if relevant:
        lines.append(
            f"  effects (significant, each explaining at least {100 * share:.0f} % of the "
            "residual), largest first; shares add up to what they explain together:"
        )
    for i, e in enumerate(relevant, start=1):
        mean = float(e.get("offset_explained") or 0.0)
        carries = (
            f"; carries {mean:+.3g}{unit} of the mean shift"
            if e["kind"] not in GENERIC_KINDS and abs(mean) > 0
            else ""
        )
        scale = float(e.get("time_scale_s") or 0.0)
        tested = f" (tested on {scale:g} s means)" if scale >= SLOW_SCALE_S else ""
        lines.append(
            f"   {i}. {e['text']}: explains {100 * e['share']:.1f} % of the residual"
            f"{carries}{tested}"
        )
        if e.get("members"):
            lines.append(
                "      one effect, also measured by: " + ", ".join(map(_label, e["members"]))
            )
        if e.get("interchangeable"):
            lines.append(
                "      on this record, interchangeable with: " + ", ".join(e["interchangeable"])
            )
        if e.get("predicted") and before:
            lines.append(f"      after adding it: {_lambda_change(before, e['predicted'])}")
    for e in stand_ins:
        instead = ", ".join(e["stands_in_for"])
        lines.append(
            f"  could stand in for {instead} on this record, not a finding of its own: "
            f"{e['text']} ({_share_text(e['share'])})"
        )
    if minor:
        lines.append(
            f"  minor (significant, but under {100 * share:.0f} % each or not helping alone): "
            + "; ".join(f"{e['text']} ({_share_text(e['share'])})" for e in minor)
        )
    if len(relevant) > 1 and found.get("predicted") and before:
        lines.append(
            f"  after adding all {len(relevant)}: {_lambda_change(before, found['predicted'])}"
        )
    for r in found.get("responses") or []:
        how = (
            "declared a response in the spec"
            if r["reason"] == "declared"
            else f"the measured signal explains {100 * r['measured_r2']:.0f} % of it, the "
            f"residual adds {100 * r['residual_r2']:.1f} %"
        )
        lines.append(
            f"  response: {r['name']} moves with {found['signal'].rsplit('/', 1)[-1]}, "
            f"probably a consequence ({how}); not offered as a cause"
        )
    where = found.get("localisation")
    if where and where.get("windows"):
        spans = ", ".join(f"{a:.0f}–{b:.0f} s" for a, b in where["spans_s"][:3])
        more = " …" if len(where["spans_s"]) > 3 else ""
        text = (
            f"  where: {100 * where['error_share']:.0f} % of the squared residual lies in "
            f"{100 * where['time_share']:.0f} % of the time, in {where['windows']} window(s) of "
            f"{where['window_s']:g} s: {spans}{more}"
        )
        if relevant and relevant[0].get("hot_share") is not None:
            first = relevant[0]
            hot = 100 * first["hot_share"]
            text += (
                f"; {first['name']} removes {hot:.0f} % of it there"
                if hot >= 0
                else f"; {first['name']} does not explain it there (it would add {-hot:.0f} %)"
            )
        lines.append(text)
    return lines


def _strongest_finding(found: dict[str, Any]) -> tuple[float, float]:
    """How well a diagnosis names a cause: the share of its largest relevant effect that is a
    channel, expression or derivative (a gain, offset or lag names no cause), then the largest
    share of the residual one significant candidate explains alone."""
    named = max(
        (
            float(e["share"])
            for e in found.get("effects", [])
            if e["relevant"] and e["kind"] not in GENERIC_KINDS
        ),
        default=0.0,
    )
    alone = max(
        (float(c["explained_fraction"]) for c in found.get("candidates", []) if c["significant"]),
        default=0.0,
    )
    return named, alone


def diagnose_origin(evaluation: Evaluation, path: str) -> dict[str, Any]:
    """Diagnose the signal where an error appears, looking one level down when it emerges.

    When the origin has children (they pass, and the error emerges where they combine), the
    origin's own residual may be a running sum or a product, and the weakest child's residual
    often names the cause more directly: a missing load shows in the power at each instant,
    while in the energy it is a slow drift that any warming temperature can mimic. Both are
    diagnosed and the one that names a cause (a relevant channel, expression or derivative)
    with the larger share is returned, else the one with the stronger significant finding,
    with ``diagnosed`` saying which.
    """
    found = diagnose_signal(evaluation, path)
    found["diagnosed"] = path
    result = evaluation.result
    node = result.signal(path)
    if node.children:
        weakest = min(
            (result.signal(child) for child in node.children),
            key=lambda s: sum(s.lambdas[name] for name in FUSED_CHARACTERISTICS),
        )
        below = diagnose_signal(evaluation, weakest.path)
        if _strongest_finding(below) > _strongest_finding(found):
            below["diagnosed"] = weakest.path
            below["summary"] = f"(in {weakest.path}, below {path}) {below['summary']}"
            return below
    return found


def _describe(found: dict[str, Any]) -> list[str]:
    unit = f" {found['unit']}" if found.get("unit") else ""
    origin = found["origin"]
    lines = [
        f"{found['signal']}: the error appears at {origin['path']} (level {origin['level']})",
        f"  {found['summary']}",
        f"  timing: lag {found['lag_s']:+.3g} s"
        + (" (significant)" if found.get("timing_significant") else ""),
        # The headline fit is the simulated signal alone against the reference; the effects
        # below are fitted together, so their gain and offset can differ.
        "  before any effect, reference ≈ gain · simulated + offset:",
        f"    gain {found['gain']:.4g} [{found['gain_interval'][0]:.4g}, "
        f"{found['gain_interval'][1]:.4g}]"
        + (" (significant)" if found["gain_significant"] else ""),
        f"    offset {found['offset']:+.4g}{unit} [{found['offset_interval'][0]:.4g}, "
        f"{found['offset_interval'][1]:.4g}]"
        + (" (significant)" if found["offset_significant"] else ""),
    ]
    candidates = found.get("candidates", [])
    if candidates:
        lines.append("  candidates (best first): explained alone / jointly, coefficient [95 % CI]")
        for item in candidates[:10]:
            joint = item.get("joint_explained_fraction")
            joint_text = "   -  " if joint is None else f"{100 * joint:5.1f}%"
            interval = item.get("interval") or [math.nan, math.nan]
            mark = "*" if item.get("significant") else " "
            lines.append(
                f"   {mark} {item['name']} ({item['kind']}): "
                f"{100 * item['explained_fraction']:5.1f}% / {joint_text}, "
                f"{item['coefficient']:.4g} [{interval[0]:.4g}, {interval[1]:.4g}]"
            )
    lines.extend(_describe_effects(found))
    remaining = found.get("remaining") or {}
    if remaining:
        verdict = "white" if remaining.get("white") else "not white"
        lines.append(
            f"  what remains: Ljung-Box lags {remaining.get('lags')}: p = "
            f"{remaining.get('p_value', math.nan):.3g} ({verdict}); dominant frequencies "
            + ", ".join(f"{f:.3g} Hz" for f in found.get("dominant_frequencies_hz", []))
        )
    return lines


def diagnose_main(argv: Sequence[str]) -> int:
    """``hevval diagnose ...``: kept for callers of the old entry point."""
    from .cli import main

    return main(["diagnose", *argv])


def run_diagnose(args: argparse.Namespace) -> int:
    """``hevval diagnose``: trace the residual of a signal to the effect the model lacks."""
    from .run import RunOptions, run_specs
    from .spec.load import load_specs

    specs = load_specs(args.spec)
    if len(specs) > 1:
        raise SpecError(
            f"the spec is a campaign of {len(specs)} recordings; diagnose one at a time",
            file=args.spec,
            hint=f"name one: hevval diagnose '{args.spec}::{specs[0].recording}'",
        )
    (spec,) = specs
    (outcome,) = run_specs([spec], RunOptions(rootdir=Path.cwd(), keep_arrays=True))
    if isinstance(outcome, HevvalError):
        raise outcome
    evaluation = outcome
    paths = args.signal or [s.path for s in evaluation.result.signals if s.origin]
    if not paths:
        print(f"{spec.name}: every signal passes; pass --signal PATH to diagnose one anyway")
    findings = [diagnose_signal(evaluation, p, channels=not args.no_channels) for p in paths]
    for found in findings:
        for line in _describe(found):
            print(line)
    if args.json:
        from .cli import _write_json

        payload: dict[str, Any] = {"spec": spec.name, "signals": findings}
        if len(findings) == 1:
            # One signal: its fields also sit at the top level, as documented.
            payload.update(findings[0])
        _write_json(args.json, payload)
    return 0
