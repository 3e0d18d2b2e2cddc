"""Residual diagnosis of a scored spec: from an evaluation to candidate effects and back.

The maths lives in :mod:`pytest_hevval.core.diagnosis`; this module gathers the candidates —
the spec's declared ``candidates:`` expressions, every measured reference channel the spec
does not use, and the time derivative of each — on the aligned grid, and formats findings.
"""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .core.diagnosis import Candidate, diagnose_residual
from .core.registry import FUSED_CHARACTERISTICS
from .data.record import Record
from .engine import Evaluation
from .errors import DataError, HevvalError, SpecError

__all__ = ["candidates_for", "diagnose_main", "diagnose_origin", "diagnose_signal"]

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
        add(f"d/dt {name}", "derivative", np.gradient(_smoothed(on_grid, smoothing), time))
    return found


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
    diagnosis = diagnose_residual(
        reference,
        simulated,
        dt=evaluation.aligned.grid.dt,
        candidates=candidates_for(evaluation, channels=channels),
        max_lag_s=evaluation.spec.alignment.max_lag_s,
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
    return payload


def _strongest_finding(found: dict[str, Any]) -> float:
    """The largest share of the residual that one significant candidate explains alone."""
    return max(
        (float(c["explained_fraction"]) for c in found.get("candidates", []) if c["significant"]),
        default=0.0,
    )


def diagnose_origin(evaluation: Evaluation, path: str) -> dict[str, Any]:
    """Diagnose the signal where an error appears, looking one level down when it emerges.

    When the origin has children (they pass, and the error emerges where they combine), the
    origin's own residual may be a running sum or a product, and the weakest child's residual
    often names the cause more directly. Both are diagnosed and the one with the stronger
    significant finding is returned, with ``diagnosed`` saying which.
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
        f"  gain: {found['gain']:.4g} [{found['gain_interval'][0]:.4g}, "
        f"{found['gain_interval'][1]:.4g}]"
        + (" (significant)" if found["gain_significant"] else ""),
        f"  offset: {found['offset']:+.4g}{unit} [{found['offset_interval'][0]:.4g}, "
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
