"""How often the diagnosis names the measured missing effect first, on real recordings.

    python benchmarks/bench_diagnosis_real.py                      # every trip, about a minute
    python benchmarks/bench_diagnosis_real.py --trips A01,B03 --misses
    python benchmarks/bench_diagnosis_real.py --data DIR --json out.json   # your own Trip*.csv

Nothing is injected: the missing effect is one the car logged. The i3 model v1 (flat road,
constant auxiliary load) is scored on each trip by the spec i3-B03-winter-v1 with the trip as
reference and ``alignment: {max_lag_s: 5, nan: omit}`` (B34's scored SoC is NaN after 293 s, so
only those 293 s count), and ``E_batt/P_batt`` is diagnosed with default settings on every
trip of the data folder (../shared/... beside the repository, or ``--data``): once with the
14 columns the example project keeps of each log ("example": the columns of its Parquet
copies, taken from the CSV, so every trip is in both sets), once with the full 23–48-column
CSV log ("full"), where many more channels compete. Without the folder, the example's ten
Parquet copies are the example set.

Truth is the logged heater: a heater trip when it is a winter trip (category B) and
``Heating Power CAN [kW]`` has σ ≥ 0.9 kW over the scored samples, else a control. Summer trips
(category A) are controls whatever that channel says: the dataset's README finds it unreliable
there (5.3–5.5 kW at 26–33 °C). A heater trip is right when its first relevant effect is the
heater as a group (its name or a member matches ``heat(ing|er)``, not temperature or voltage)
with a positive coefficient. A control has a false finding when a relevant channel, derivative
or declared effect is a response, echo or level: anything but the loads (heater, air
conditioning) and the road-load terms the spec declares (``climb_rate_m_s``, ``aero_kw``,
``inertia_kw``: v1 drives on a flat road with fitted drag, so a hilly trip's climb rate is a
real missing effect); gain, offset, lag and those count apart. B02's heater
σ comes from a 160-s gap filled by linear interpolation (example_project/data/i3/README.md).

On each heater trip the first finding's printed fix (the ``--try`` term ``hevval diagnose``
prints: the term over the spec's candidates and the log's columns, constant included) is
applied to the model as a user would: evaluated over the trip as ``--try`` evaluates it, added
to model v1 as an electrical load (``v1_with_fix``: ``models.ev.simulate(...,
auxiliary_w=1e3 * term)``), and the whole spec is run again through the normal pipeline. The
table gives P_batt's and E_batt's λ3 and λ4 before → after, with what the diagnosis predicted
(E_batt's from the fix integrated as the model integrates P_batt), whether both λ improve on
both signals, and whether both predictions are within 0.01 of the re-run model's.

The Camry cold bag (FTP bag 1, started cold, model fitted warm) lacks the cold start: extra fuel
early in the bag, fading as the engine warms; its size is the fuel-rate residual over the FTP's
cold transient phase (0–505 s) above the rest. The file holds only time, fuel and dyno speed, so
the spec declares the suspect a user would (``warm_up: exp(-t / 300 s)``, a cause). Each signal
is diagnosed as a failing test does (``diagnose_origin``: the cumulative fuel looks one level
down, where the extra fuel shows at each instant); right is ``warm_up`` first, with a positive
coefficient.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pytest_hevval.report.diagnosis_text import fix_expression, payload
from pytest_hevval.scoring.candidates import candidates_for
from pytest_hevval.scoring.diagnosis import diagnose_origin, diagnose_signal
from pytest_hevval.scoring.fixes import term_values
from pytest_hevval.scoring.run import RunOptions, run_specs
from pytest_hevval.spec.load import parse_spec_text

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "example_project"
TEMPLATE = EXAMPLE / "specs/i3-B03-winter-v1.hevval.yaml"
FULL = ROOT.parent / "shared/data/real/tum-bmw-i3-real-driving-via-hardikjain98"
CAMRY = EXAMPLE / "specs/camry-ftp-cold-bag.hevval.yaml"
# What the cumulative fuel's first relevant effect must be; None: nothing offered can say it.
CAMRY_SIGNALS = ("FC_cum", "FC_cum/FC_rate")
CAMRY_TRUTH = "warm_up"
COLD_PHASE_S = 505.0  # the FTP's cold transient phase (bag 1 of the 3-bag FTP)
SIGNAL = "E_batt/P_batt"
ENERGY = "E_batt"
#: λ3 and λ4, the characteristics the diagnosis predicts.
PREDICTED = ("mae", "rms")
HEATER_LOG = "Heating Power CAN [kW]"
HEATER_STD_KW = 0.9
HEATER = re.compile(r"(?i)heat(ing|er)")
NOT_HEATER = re.compile(r"(?i)temperature|voltage")
AIRCON = re.compile(r"(?i)air ?con")
# The spec's declared road-load terms: physics model v1 lacks or misfits, not echoes.
ROAD_LOAD = ("climb_rate_m_s", "aero_kw", "inertia_kw")
SERIES = ("channel", "derivative", "declared")

Row = dict[str, Any]


def is_heater(name: str) -> bool:
    return bool(HEATER.search(name)) and not NOT_HEATER.search(name)


def evaluate(spec_text: str, template: Path) -> Any:
    spec = parse_spec_text(spec_text, template)
    (outcome,) = run_specs([spec], RunOptions(rootdir=Path.cwd(), keep_arrays=True))
    return outcome


def kept(evaluation: Any) -> Any:
    mask = evaluation.aligned.gap_mask
    return slice(None) if mask is None else ~mask.copy()


def first_of(found: dict[str, Any]) -> dict[str, Any] | None:
    first = next((e for e in found["effects"] if e["relevant"]), None)
    # `members` (the effect's correlated group) may be absent from older diagnoses.
    return first and {k: first.get(k) for k in ("name", "kind", "coefficient", "share", "members")}


def rate(part: int, whole: int) -> str:
    return f"{part}/{whole} ({100 * part / whole:.0f} %)" if whole else "—"


def trip_row(path: Path, channel_set: str) -> Row:
    started = time.perf_counter()
    doc = yaml.safe_load(TEMPLATE.read_text(encoding="utf-8"))
    doc["reference"]["path"] = str(path.resolve())
    doc["alignment"] = {"max_lag_s": 5, "nan": "omit"}
    row: Row = {"set": channel_set, "trip": path.stem.removeprefix("Trip")}
    evaluation = evaluate(yaml.safe_dump(doc, allow_unicode=True, sort_keys=False), TEMPLATE)
    if isinstance(evaluation, Exception):
        return {**row, "verdict": "unscored", "summary": str(evaluation).splitlines()[0]}
    # Taken before the heater column is read: reading it must not change which samples count.
    keep = kept(evaluation)
    heater = evaluation.aligned.column("reference", HEATER_LOG, "linear")[keep]
    found = payload(diagnose_signal(evaluation, SIGNAL))
    relevant = [e for e in found["effects"] if e["relevant"]]
    first = first_of(found)
    row.update(
        heater_std_kw=float(np.nanstd(heater)),
        samples=len(evaluation.arrays[SIGNAL][0]),
        candidates=len(candidates_for(evaluation)),
        first=first,
        members=list((first or {}).get("members") or []),
        summary=found["summary"],
    )
    winter = row["trip"].startswith("B")
    row["truth"] = "heater" if winter and row["heater_std_kw"] >= HEATER_STD_KW else "control"
    load = [
        e["name"]
        for e in relevant
        if is_heater(e["name"]) or AIRCON.search(e["name"]) or e["name"] in ROAD_LOAD
    ]
    row["false"] = [e["name"] for e in relevant if e["kind"] in SERIES and e["name"] not in load]
    row["generic_or_load"] = sum(e["kind"] not in SERIES or e["name"] in load for e in relevant)
    if row["truth"] == "heater":
        group = [first["name"], *row["members"]] if first else []
        hit = first is not None and first["coefficient"] > 0 and any(map(is_heater, group))
        row["verdict"] = "right" if hit else "wrong"
        row["fix"] = applied_fix(evaluation, found, doc, f"{channel_set} {row['trip']}")
    else:
        row["verdict"] = "false" if row["false"] else "ok"
    row["seconds"] = time.perf_counter() - started
    return row


#: Each heater trip's fix under test on the aligned grid: (time s, load kW), by trip.
FIX_LOADS: dict[str, tuple[Any, Any]] = {}


def v1_with_fix(reference: Any, *, fix: str, **params: Any) -> Any:
    """Model v1 (``models.ev.simulate``) with the fix registered under ``fix`` as one more
    electrical load: the spec's ``model.callable`` for the re-run (``__main__:v1_with_fix``)."""
    from models.ev import TIME, simulate

    grid, load_kw = FIX_LOADS[fix]
    at = reference[TIME].to_numpy(dtype=np.float64)
    return simulate(reference, auxiliary_w=1e3 * np.interp(at, grid, load_kw), **params)


def applied_fix(
    evaluation: Any, found: dict[str, Any], doc: dict[str, Any], key: str
) -> Row | None:
    """The first finding's printed fix applied to model v1 and the whole spec run again:
    P_batt's and E_batt's λ3 and λ4 before, after, and as the diagnosis predicted them."""
    first = next((e for e in found["effects"] if e["relevant"]), None)
    term = None if first is None else fix_expression(first)
    if first is None or term is None:
        return None
    # The term as --try evaluates it, on the whole grid; a gap the model would see as NaN is
    # bridged linearly, as the spec bridges its channels.
    grid = evaluation.aligned.time
    load = term_values(evaluation, term)
    finite = np.isfinite(load)
    FIX_LOADS[key] = (grid, np.interp(grid, grid[finite], load[finite]))
    fixed = {**doc, "model": {**doc["model"], "callable": "__main__:v1_with_fix"}}
    fixed["model"]["params"] = {**doc["model"].get("params", {}), "fix": key}
    outcome = evaluate(yaml.safe_dump(fixed, allow_unicode=True, sort_keys=False), TEMPLATE)
    if isinstance(outcome, Exception):
        return {"term": term, "error": str(outcome).splitlines()[0]}
    above = {a["signal"]: a["predicted"] for a in first.get("above") or []}
    predicted = {SIGNAL: first.get("predicted") or {}, ENERGY: above.get(ENERGY, {})}
    return {
        "term": term,
        **{
            path: {
                "before": [evaluation.result.signal(path).lambdas[k] for k in PREDICTED],
                "after": [outcome.result.signal(path).lambdas[k] for k in PREDICTED],
                "predicted": [predicted[path].get(k) for k in PREDICTED],
            }
            for path in (SIGNAL, ENERGY)
        },
    }


def _fix_cell(figures: dict[str, Any], i: int) -> str:
    before, after, predicted = (figures[k][i] for k in ("before", "after", "predicted"))
    guess = "none" if predicted is None else f"{predicted:.4f}"
    return f"{before:.4f} → {after:.4f} ({guess})"


def _fix_verdicts(fix: Row) -> tuple[bool, bool]:
    """Whether both λ improve on both signals, and whether every prediction is within 0.01."""
    figures = [fix[path] for path in (SIGNAL, ENERGY)]
    better = all(a > b for f in figures for b, a in zip(f["before"], f["after"], strict=True))
    close = all(
        p is not None and abs(a - p) <= 0.01
        for f in figures
        for a, p in zip(f["after"], f["predicted"], strict=True)
    )
    return better, close


def fix_table(rows: list[Row]) -> str:
    lines = [
        "| trip | set | printed fix (--try term) | P_batt λ3 before → after (predicted) "
        "| P_batt λ4 | E_batt λ3 | E_batt λ4 | improves | predicted within 0.01 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    counts = {"trips": 0, "fixed": 0, "better": 0, "close": 0}
    for r in rows:
        fix = r.get("fix")
        if r.get("truth") != "heater" or r.get("verdict") == "unscored":
            continue
        counts["trips"] += 1
        if not fix:
            lines.append(f"| {r['trip']} | {r['set']} | no fix printed | | | | | no | |")
            continue
        if "error" in fix:
            lines.append(f"| {r['trip']} | {r['set']} | `{fix['term']}`: {fix['error']} |||||no||")
            continue
        better, close = _fix_verdicts(fix)
        counts["fixed"] += 1
        counts["better"] += better
        counts["close"] += close
        cells = [_fix_cell(fix[path], i) for path in (SIGNAL, ENERGY) for i in (0, 1)]
        lines.append(
            f"| {r['trip']} | {r['set']} | `{fix['term']}` | {' | '.join(cells)} "
            f"| {'yes' if better else 'no'} | {'yes' if close else 'no'} |"
        )
    lines.append(
        f"\n{counts['trips']} heater trips, {counts['fixed']} with a fix applied to model v1: "
        f"λ3 and λ4 of P_batt and E_batt improve on {rate(counts['better'], counts['fixed'])}, "
        f"predicted within 0.01 on {rate(counts['close'], counts['fixed'])}"
    )
    return "\n".join(lines)


def camry_rows() -> list[Row]:
    evaluation = evaluate(CAMRY.read_text(encoding="utf-8"), CAMRY)
    # The example's own spec: failing to score it is a bug to see, not a row to tabulate.
    if isinstance(evaluation, Exception):
        raise evaluation
    measured, simulated = evaluation.arrays["FC_cum/FC_rate"]
    since = evaluation.aligned.time[kept(evaluation)]
    cold = since - since[0] < COLD_PHASE_S
    residual = measured - simulated
    excess = float(np.mean(residual[cold]) - np.mean(residual[~cold]))
    rows: list[Row] = []
    for signal in CAMRY_SIGNALS:
        started = time.perf_counter()
        found = payload(diagnose_origin(evaluation, signal))
        first = first_of(found)
        spans = (found.get("localisation") or {}).get("spans_s") or []
        hit = first is not None and first["name"] == CAMRY_TRUTH and first["coefficient"] > 0
        verdict = "right" if hit else "wrong"
        rows.append(
            {
                "signal": signal,
                "diagnosed": found["diagnosed"],
                "samples": len(evaluation.arrays[signal][0]),
                "candidates": len(candidates_for(evaluation)),
                "first": first,
                "excess_ccps": excess,
                "spans_s": spans,
                "verdict": verdict,
                "summary": found["summary"],
                "seconds": time.perf_counter() - started,
            }
        )
    return rows


def example_copies(csvs: list[Path], folder: Path) -> list[Path]:
    """Each full log cut to the columns the example's Parquet copies keep, as the example's
    import does (values and names untouched, no row dropped)."""
    import pandas as pd

    columns = list(pd.read_parquet(EXAMPLE / "data/i3/TripA01.parquet").columns)
    copies = []
    for path in csvs:
        frame = pd.read_csv(path, sep=";", encoding="latin-1")
        copy = folder / f"{path.stem}.parquet"
        frame[columns].to_parquet(copy)
        copies.append(copy)
    return copies


def finding(row: Row) -> str:
    first = row.get("first")
    if not first:
        return "—"
    return f"{first['name']} ({first['coefficient']:+.3g}, {100 * first['share']:.0f} %)"


def trips_table(rows: list[Row]) -> str:
    lines = [
        "| trip | set | truth (σ heater) | samples | candidates | first finding (coef, share) "
        "| members | verdict | s |",
        "|---|---|---|---:|---:|---|---|---|---:|",
    ]
    for r in rows:
        if r["verdict"] == "unscored":
            lines.append(f"| {r['trip']} | {r['set']} | | | | {r['summary']} | | unscored | |")
            continue
        more = len(r["members"]) - 3
        members = ", ".join(r["members"][:3] + ([f"+{more} more"] if more > 0 else []))
        false = r["false"] if r["verdict"] == "false" else []
        verdict = ": ".join([r["verdict"], ", ".join(false)] if false else [r["verdict"]])
        lines.append(
            f"| {r['trip']} | {r['set']} | {r['truth']} ({r['heater_std_kw']:.2f} kW) "
            f"| {r['samples']} | {r['candidates']} | {finding(r)} | {members} "
            f"| {verdict} | {r['seconds']:.1f} |"
        )
    return "\n".join(lines)


def summary_table(rows: list[Row]) -> str:
    lines = [
        "| set | trips | heater trips first right | controls with a false finding "
        "| generic or load on controls |",
        "|---|---:|---:|---:|---:|",
    ]
    for name in [*dict.fromkeys(r["set"] for r in rows), "all"]:
        scored = [r for r in rows if name in ("all", r["set"]) and r["verdict"] != "unscored"]
        heater = [r for r in scored if r["truth"] == "heater"]
        control = [r for r in scored if r["truth"] == "control"]
        right = sum(r["verdict"] == "right" for r in heater)
        false = sum(r["verdict"] == "false" for r in control)
        generic = sum(r["generic_or_load"] for r in control)
        lines.append(
            f"| {name} | {len(scored)} | {rate(right, len(heater))} "
            f"| {rate(false, len(control))} | {generic} |"
        )
    return "\n".join(lines)


def camry_table(rows: list[Row]) -> str:
    lines = [
        "| signal | diagnosed at | samples | candidates | first finding (coef, share) "
        "| cold-phase excess | hot spans (s) | verdict |",
        "|---|---|---:|---:|---|---:|---|---|",
    ]
    for r in rows:
        spans = ", ".join(f"{a:.0f}–{b:.0f}" for a, b in r["spans_s"]) or "—"
        lines.append(
            f"| {r['signal']} | {r['diagnosed']} | {r['samples']} | {r['candidates']} "
            f"| {finding(r)} "
            f"| {r['excess_ccps']:+.3f} cm³/s | {spans} | {r['verdict']} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=FULL, help="folder of full Trip*.csv logs")
    parser.add_argument("--trips", default="", help="comma-separated trips, e.g. A01,B03")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--misses", action="store_true", help="summary of every wrong/false case")
    args = parser.parse_args()
    data = args.data.resolve()
    output = args.json.resolve() if args.json else None
    # The example's model package is imported from the example folder, as its specs expect.
    os.chdir(EXAMPLE)
    sys.path.insert(0, str(EXAMPLE))
    wanted = {t.strip().removeprefix("Trip") for t in args.trips.split(",") if t.strip()}
    sets = {"example": sorted((EXAMPLE / "data/i3").glob("Trip*.parquet"))}
    notes: list[str] = []
    scratch = tempfile.TemporaryDirectory()
    if data.is_dir():
        full = [p for p in sorted(data.glob("Trip*.csv")) if not wanted or p.stem[4:] in wanted]
        sets = {"example": example_copies(full, Path(scratch.name)), "full": full}
    else:
        notes.append(f"note: no folder {data}; the full set is skipped")
        print(notes[-1], file=sys.stderr)
    started = time.perf_counter()
    rows: list[Row] = []
    for channel_set, paths in sets.items():
        for path in paths:
            if not wanted or path.stem.removeprefix("Trip") in wanted:
                rows.append(trip_row(path, channel_set))
                print(f"{channel_set} {path.stem}: {rows[-1]['verdict']}", file=sys.stderr)
    scratch.cleanup()
    camry = camry_rows()
    elapsed = time.perf_counter() - started
    print(trips_table(rows), summary_table(rows), fix_table(rows), camry_table(camry), sep="\n\n")
    print("", *(f"{CAMRY.name} {r['signal']}: {r['summary']}" for r in camry), sep="\n")
    print("", *notes, sep="\n")
    if args.misses:
        for r in [*rows, *camry]:
            if r["verdict"] in ("wrong", "false", "unscored"):
                where = f"{r['set']} {r['trip']}" if "trip" in r else f"camry {r['signal']}"
                print(f"{where} ({r['verdict']}): {r['summary']}")
    print(f"\n{len(rows) + len(camry)} diagnoses in {elapsed:.0f} s")
    if output:
        payload = {"trips": rows, "camry": camry, "seconds": elapsed}
        output.write_text(json.dumps(payload, indent=1, default=str), encoding="utf-8")


if __name__ == "__main__":
    main()
