"""The diagnosis in words: the one-line summary, each effect in physical units, and the
full description ``hevval diagnose`` prints. The numbers come from
:mod:`pytest_hevval.core.residual`; only sentences are made here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..core.registry import FUSED_CHARACTERISTICS, get_characteristic
from ..core.residual import (
    GENERIC_KINDS,
    MIN_EXPLAINED_INCREASE,
    MIN_SHARE,
    SLOW_SCALE_S,
    Diagnosis,
    Effect,
    Note,
    Response,
)
from ..errors import HevvalError
from ..results.signal_diagnosis import SignalDiagnosis, candidate_unit
from .sentences import lag_bound_text

__all__ = [
    "SUMMARY_NAMES",
    "describe",
    "effect_text",
    "fix_expression",
    "fix_text",
    "note_text",
    "payload",
    "summary",
    "target_payload",
    "tried_lines",
    "tried_payload",
]

EXACT_MATCH = "the model matches the reference exactly: the residual is zero"


def payload(found: SignalDiagnosis) -> dict[str, Any]:
    """The JSON form of a diagnosis with its sentences: the summary and each effect's text."""
    out = found.to_dict()
    out["notes"] = [note_text(note) for note in found.diagnosis.notes]
    out["summary"] = summary(found)
    name = found.signal.rsplit("/", 1)[-1]
    for effect in out["effects"]:
        effect["text"] = effect_text(effect, name, found.unit)
        effect["fix"] = fix_text(effect, name, found.unit)
        # What the fix, integrated as the model integrates the signal, does to the signals
        # above it.
        effect["above"] = [
            {"signal": a["signal"], "unit": a["unit"], "predicted": a["predicted"][effect["name"]]}
            for a in out["above"]
            if effect["name"] in a["predicted"]
        ]
        effect["then"] = then_text(effect, out)
    return out


def note_text(note: Note) -> str:
    """What the diagnosis dropped or changed, and why, in words."""
    if note.kind == "constant_simulation":
        return "the simulated signal is constant: gain and lag cannot be estimated"
    if note.kind == "decimated":
        return f"regressions use block means of {note.samples} samples ({note.seconds:g} s)"
    if note.kind == "constant":
        return f"candidate {note.candidate!r} is constant and was dropped"
    if note.kind == "duplicate":
        return f"candidate {note.candidate!r} duplicates {note.other!r} and was dropped"
    return (
        f"candidate {note.candidate!r} is (nearly) a linear combination of the candidates "
        "before it and was dropped"
    )


def then_text(effect: Mapping[str, Any], found: Mapping[str, Any]) -> str | None:
    """The λ the diagnosis predicts once an effect's fix is in the model: the signal's, then
    those of the signals above it that the model integrates from it, e.g. ``λ3 0.9808 →
    0.9838, λ4 0.9722 → 0.9744; E_batt λ3 0.8012 → 0.9551, λ4 0.7467 → 0.9420``; None when
    nothing is predicted."""
    before = found.get("lambdas") or {}
    parts = [_lambda_change(before, effect["predicted"])] if effect.get("predicted") else []
    above = {a["signal"]: a for a in found.get("above") or []}
    for item in effect.get("above") or []:
        now = above[item["signal"]]["lambdas"]
        name = item["signal"].rsplit("/", 1)[-1]
        parts.append(f"{name} {_lambda_change(now, item['predicted'])}")
    return "; ".join(p for p in parts if p) or None


def target_payload(spec: str, target: str, found: SignalDiagnosis | HevvalError) -> dict[str, Any]:
    """The payload of a failing signal's diagnosis, or of why it could not be diagnosed."""
    if isinstance(found, HevvalError):
        return {"spec": spec, "signal": target, "summary": f"not diagnosed: {found}"}
    return payload(found)


def summary(found: SignalDiagnosis | Diagnosis) -> str:
    """One line: the relevant effects with their shares, what else is worth a word."""
    if isinstance(found, SignalDiagnosis):
        text = summary(found.diagnosis)
        if found.asked is not None and found.asked != found.signal:
            return f"(in {found.signal}, below {found.asked}) {text}"
        return text
    if found.exact_match:
        return EXACT_MATCH
    return _summary(
        found.effects,
        found.responses,
        lag_s=found.lag_s,
        lag_at_bound=found.lag_at_bound,
        timing_significant=found.timing_significant,
        remaining=found.remaining,
        headline=[
            *(["gain"] if found.gain_significant else []),
            *(["offset"] if found.offset_significant else []),
        ],
    )


def _format_pct(fraction: float) -> str:
    return f"{100.0 * fraction:.0f} %"


#: The summary names at most this many effects or channels per list; the full output and the
#: JSON hold the rest.
SUMMARY_NAMES = 3


def _names_text(names: Sequence[str]) -> str:
    """At most :data:`SUMMARY_NAMES` names, the rest counted; trailing spaces shown as such,
    so that two logged columns that differ only by one stay apart."""
    shown = [repr(n) if n != n.strip() else n for n in names[:SUMMARY_NAMES]]
    rest = len(names) - len(shown)
    return ", ".join(shown) + (f" and {rest} more" if rest > 0 else "")


def _effect_phrase(e: Effect) -> str:
    """One effect, with the numbers every output shows for it: its share of the residual and
    its coefficient with its interval."""
    share = f"explains {_format_pct(e.share)} of the residual"
    low, high = e.interval
    if e.kind == "gain":
        return (
            f"gain error {100.0 * e.coefficient:+.1f} % [{100.0 * low:+.1f}, {100.0 * high:+.1f}]"
            f" {share}"
        )
    if e.kind == "offset":
        return f"offset {e.coefficient:+.3g} [{low:.3g}, {high:.3g}] {share}"
    if e.kind == "lag":
        direction = "lags" if e.coefficient > 0 else "leads"
        # The interval of the delay in the direction named: "leads by 0.9 s [0.69, 1.1]".
        if e.coefficient < 0:
            low, high = -high, -low
        return (
            f"the simulation {direction} the reference by {abs(e.coefficient):.2g} s "
            f"[{low:.3g}, {high:.3g}], which {share}"
        )
    group = f" (one effect with {_names_text(e.members)})" if e.members else ""
    return f"{e.name}{group} {share} (coef {e.coefficient:+.3g} [{low:.3g}, {high:.3g}])"


def _summary(
    effects: Sequence[Effect],
    echoes: Sequence[Response],
    *,
    lag_s: float,
    lag_at_bound: bool,
    timing_significant: bool,
    remaining: Any,
    headline: Sequence[str] = (),
) -> str:
    parts = [_effect_phrase(e) for e in effects if e.relevant]
    if timing_significant and not any(e.relevant and e.kind == "lag" for e in effects):
        direction = "lags" if lag_s < 0 else "leads"
        edge = " or more (the edge of the lag search)" if lag_at_bound else ""
        parts.append(f"the simulation {direction} the reference by {abs(lag_s):.3g} s{edge}")
    stand_ins = [e for e in effects if e.stands_in_for]
    minor = [e.name for e in effects if e.significant and not e.relevant and not e.stands_in_for]
    if not parts:
        text = "no significant effect found: the residual is indistinguishable from noise"
        if minor or stand_ins:
            text = "no relevant effect found"
        elif headline:
            # The simulated signal itself is off (its own fit says so), but no candidate,
            # gain term included, explains enough of the residual to be named.
            text = (
                "no significant effect found among the candidates, though the headline fit "
                f"finds the simulated signal's {' and '.join(headline)} off"
            )
        elif not remaining.white:
            text += " (autocorrelated noise; an effect outside the candidates is not excluded)"
        parts.append(text)
    elif not remaining.white:
        parts.append("the remaining residual is still autocorrelated")
    for e in stand_ins:
        parts.append(f"{e.name} could stand in for {_names_text(e.stands_in_for)} on this record")
    if minor:
        parts.append("minor: " + _names_text(minor))
    # Only the responses that would have been offered as an effect are worth a word here.
    loud = [e for e in echoes if e.explains >= MIN_EXPLAINED_INCREASE]
    echoed = [e.name for e in loud if e.reason == "echo"]
    reproduced = [e.name for e in loud if e.reason == "reproduced"]
    follows = [e.name for e in loud if e.reason not in ("echo", "reproduced")]
    if echoed:
        parts.append(f"echoes the measured signal, never a cause: {_names_text(echoed)}")
    if reproduced:
        parts.append(f"reproduced by the model through its inputs: {_names_text(reproduced)}")
    if follows:
        parts.append(
            f"moves with the simulated signal, probably a consequence: {_names_text(follows)}"
        )
    return "; ".join(parts)


def fix_expression(effect: Mapping[str, Any]) -> str | None:
    """The fix as a term ``hevval diagnose --try`` reads, to full precision; None for a gain,
    a lag or a derivative, which no expression over the reference's columns writes exactly."""
    kind = str(effect["kind"])
    constant = float(effect.get("fix_constant") or 0.0)
    if kind == "offset":
        return f"{constant:.6g}"
    if kind not in ("channel", "declared"):
        return None
    name = str(effect["name"])
    quoted = name if name.isidentifier() else f"`{name}`"
    sign = "-" if constant < 0 else "+"
    return (
        f"{float(effect.get('fix_coefficient') or 0.0):.6g} * {quoted} {sign} {abs(constant):.6g}"
    )


def tried_lines(tried: Any) -> list[str]:
    """The before/after of ``hevval diagnose --try``: each λ and the physical errors of the
    signal as the spec scores it, before and after the term is added to the model's output;
    then the same for each signal above it that the model integrates from it."""
    lines = [
        f"{tried.signal} with {tried.term} added to the model's output, scored through the spec:",
        *_before_after_lines(tried.before, tried.after, tried.unit),
    ]
    lower = tried.signal
    for above in tried.above:
        lines.append(
            f"{above.signal}, the model's running integral of {lower.rsplit('/', 1)[-1]}, with "
            "the term integrated the same way:"
        )
        lines.extend(_before_after_lines(above.before, above.after, above.unit))
        lower = above.signal
    if tried.above_note:
        lines.append(
            f"  (the signals above {lower.rsplit('/', 1)[-1]} are not scored again: "
            f"{tried.above_note})"
        )
    return lines


def _before_after_lines(before: Any, after: Any, unit: str | None) -> list[str]:
    """Each λ and the physical errors of one signal, before → after."""
    unit_text = f" {unit}" if unit else ""
    lambdas = ", ".join(
        f"{get_characteristic(name).symbol} {b:.4f} → {a:.4f}"
        for name, b, a in zip(FUSED_CHARACTERISTICS, before.lambdas, after.lambdas, strict=True)
    )
    return [
        f"  {lambdas}",
        f"  mean error {before.mean_error:+.4g} → {after.mean_error:+.4g}{unit_text}, "
        f"MAE {before.mae:.4g} → {after.mae:.4g}{unit_text}, "
        f"RMS {before.rms:.4g} → {after.rms:.4g}{unit_text}",
    ]


def tried_payload(tried: Any) -> dict[str, Any]:
    """The JSON form of ``hevval diagnose --try``: the signal and each signal above it that was
    scored again, before and after."""
    return {
        "signal": tried.signal,
        "term": tried.term,
        "before": tried.before.as_dict(),
        "after": tried.after.as_dict(),
        "above": [
            {"signal": a.signal, "before": a.before.as_dict(), "after": a.after.as_dict()}
            for a in tried.above
        ],
        "above_note": tried.above_note,
    }


def fix_text(effect: Mapping[str, Any], signal: str, unit: str | None) -> str:
    """The fix as the user applies it to the model, mean included: ``add 1.2 × heating_kw and
    lower the model's constant by 2.9 kW``."""
    coef = float(effect.get("fix_coefficient") or 0.0)
    constant = float(effect.get("fix_constant") or 0.0)
    unit_text = f" {unit}" if unit else ""
    kind = str(effect["kind"])
    if kind == "gain":
        action = f"multiply the model's {signal} by {1.0 + coef:.4g}"
    elif kind == "lag":
        action = f"make the model's {signal} {abs(coef):.3g} s {'earlier' if coef > 0 else 'later'}"
    elif kind == "offset":
        action = ""
    else:
        action = f"add {coef:.3g} × {_label(str(effect['name']))}"
    direction = "raise" if constant > 0 else "lower"
    shift = f"{direction} the model's constant by {abs(constant):.3g}{unit_text}"
    if not action:
        return shift
    return f"{action} and {shift}" if constant != 0.0 else action


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
    per = candidate_unit(str(effect["name"]), kind)
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
            "residual), in the order tested (loads and suspects, then the signal's own gain, "
            "offset and lag, then other channels), largest first within each; shares add up "
            "to what they explain together:"
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
        fix = fix_text(e, found["signal"].rsplit("/", 1)[-1], found.get("unit"))
        then = then_text(e, found) if before else None
        lines.append(f"      fix: {fix}" + (f" (then {then})" if then else ""))
        term = fix_expression(e)
        if term is not None:
            lines.append(
                f"      try it: hevval diagnose SPEC --signal {found['signal']} --try '{term}'"
            )
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
    if relevant and found.get("above_note"):
        top = ([found["signal"]] + [a["signal"] for a in found.get("above") or []])[-1]
        lines.append(
            f"  the fixes are not predicted for the signals above {top.rsplit('/', 1)[-1]}: "
            f"{found['above_note']}"
        )
    signal = found["signal"].rsplit("/", 1)[-1]
    for r in found.get("responses") or []:
        name = _label(r["name"])
        # Never set a candidate aside without saying how to test it as a cause.
        declare = f"to test it as a cause, declare it: diagnosis: {{causes: [{r['name']!r}]}}"
        if r["reason"] == "declared":
            lines.append(f"  response: {name} is declared a response in the spec")
        elif r["reason"] == "echo":
            lines.append(
                f"  echo: {name} echoes the measured {signal} (which explains "
                f"{100 * r['measured_r2']:.0f} % of it, or of its increments, on "
                f"{SLOW_SCALE_S:g} s means): an instrument, derivative or integral of it, not "
                f"offered as a cause; {declare}"
            )
        elif r["reason"] == "reproduced":
            lines.append(
                f"  reproduced: {name} leads the measured {signal} by {r['lead_s']:.2g} s and "
                f"moves with the simulated one (it explains {100 * r['measured_r2']:.0f} % of "
                f"it, the residual adds {100 * r['residual_r2']:.1f} %): a cause the model "
                f"already reproduces through its inputs, not offered as a cause; {declare}"
            )
        else:
            lines.append(
                f"  response: {name} moves with the simulated {signal}, probably a consequence "
                f"(the simulated signal explains {100 * r['measured_r2']:.0f} % of it, the "
                f"residual adds {100 * r['residual_r2']:.1f} %); not offered as a cause; "
                f"{declare}"
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


def _bound_text(found: Mapping[str, Any]) -> str:
    """A lag on the edge of the search says so, in the words of every scored signal's lag."""
    bound = lag_bound_text(found)
    return f", {bound}" if bound else ""


def describe(found: Mapping[str, Any]) -> list[str]:
    """The lines ``hevval diagnose`` prints for one diagnosis, from its :func:`payload`."""
    unit = f" {found['unit']}" if found.get("unit") else ""
    origin = found["origin"]
    lines = [
        f"{found['signal']}: the error appears at {origin['path']} (level {origin['level']})",
        f"  {found['summary']}",
        f"  timing: lag {found['lag_s']:+.3g} s"
        + (" (significant)" if found.get("timing_significant") else "")
        + _bound_text(found),
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
