"""How often the diagnosis names an injected effect first, on the example's real i3 trips.

    python benchmarks/bench_diagnosis_accuracy.py               # the published table, ~5 min
    python benchmarks/bench_diagnosis_accuracy.py --draws 2     # a quick look
    python benchmarks/bench_diagnosis_accuracy.py --json out.json
    python benchmarks/bench_diagnosis_accuracy.py --coverage    # intervals on real residuals

For each trip the example ships (A01, A02, A12, B03, each with its model v2 spec in
example_project/specs), the battery power ``E_batt/P_batt`` is scored once. Then, per draw, a
reference is built from the model's output, a known effect and realistic noise:

    reference = simulated + effect + noise

The noise is the trip's real residual (measured − model v2), its mean removed, shifted in time
by a random 20–80 % of the record (circularly): it keeps the real level, spectrum and
autocorrelation of a vehicle model's error, and is unrelated to the channels and to the model
output. The effects:

* ``channel``: a scaled logged channel (heater, air conditioning, elevation, ambient
  temperature, throttle), random sign; the elevation and the ambient temperature about their
  mean (their zero is arbitrary; scaled as they are, they would be mostly a constant);
* ``derivative``: a scaled derivative candidate (of the elevation, the throttle, the
  air-conditioning power), exactly as the diagnosis builds it;
* ``gain``: (g − 1) × simulated; ``offset``: a constant; ``lag``: the simulated signal delayed
  or advanced by 0.3–2 s;
* two of these at once (different kinds);
* ``control``: no effect (``--controls`` per draw, 5 by default).

Each effect's size is drawn so that it makes 20–60 % of the residual's mean square (15–40 %
each for two; the lag is drawn by its delay). The candidates are those a user gets
(``candidates_for``: the spec's own, every unscored channel and its derivative), with the spec's
diagnosis settings (``diagnose_pair``).

The first finding is right when the diagnosis' first relevant effect is the injected one (for
two, one of the two). A control has a false finding when any effect is relevant.

``--coverage`` runs the conditions that broke real trips instead (``CONDITIONS``): under each,
the logged load that varies most (the heater on every example trip) is added on top of the
shifted real residual with a known coefficient (the scale that makes it 20–60 % of the
residual's mean square), and the table counts how often it is the first finding with a
positive coefficient, how often its 95 % interval holds the coefficient, and how often a
control (the same condition, no load added: ``--controls`` per draw) gets a false finding. The
residuals are strongly autocorrelated, so this is where intervals built for white noise would
fail; under ``jitter`` and ``noisy`` the fine-scale regressor is noise, where a coefficient
fitted there is diluted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "example_project"
SPECS = (
    "specs/i3-A01-fit.hevval.yaml",
    "specs/i3-A02-motorway-v2.hevval.yaml",
    "specs/i3-A12-hills-v2.hevval.yaml",
    "specs/i3-B03-winter-v2.hevval.yaml",
)
SIGNAL = "E_batt/P_batt"
CHANNELS = (
    "Heating Power CAN [kW]",
    "AirCon Power [kW]",
    "Elevation [m]",
    "Ambient Temperature [°C]",
    "Throttle [%]",
)
# Channels whose zero means "no effect" (a load that is off, a released pedal) are injected as
# they are; a scaled elevation or ambient temperature in °C is mostly a constant, which no
# diagnosis can tell from an offset, so those are injected about their mean.
PHYSICAL_ZERO = ("Heating Power CAN [kW]", "AirCon Power [kW]", "Throttle [%]")
DERIVATIVES = ("d/dt Elevation [m]", "d/dt Throttle [%]", "d/dt AirCon Power [kW]")
KINDS = ("channel", "derivative", "gain", "offset", "lag")
SHARE_ONE = (0.2, 0.6)
SHARE_TWO = (0.15, 0.4)
LAG_S = (0.3, 2.0)

FloatArray = npt.NDArray[np.float64]


class Trip:
    """One scored trip: the model output, the real residual and the candidates."""

    def __init__(self, spec: str) -> None:
        from pytest_hevval.scoring.candidates import candidates_for
        from pytest_hevval.scoring.run import RunOptions, run_specs
        from pytest_hevval.spec.load import load_spec

        (outcome,) = run_specs([load_spec(spec)], RunOptions(rootdir=Path.cwd(), keep_arrays=True))
        if isinstance(outcome, Exception):
            raise outcome
        evaluation = outcome
        assert evaluation.aligned is not None
        self.name = Path(spec).name.split(".")[0]
        self.evaluation = evaluation
        measured, simulated = evaluation.arrays[SIGNAL]
        self.simulated = np.asarray(simulated, dtype=np.float64)
        residual = np.asarray(measured, dtype=np.float64) - self.simulated
        self.residual = residual - float(np.mean(residual))
        self.dt = evaluation.aligned.grid.dt
        self.candidates = candidates_for(evaluation)
        self.series = {c.name: np.asarray(c.values, dtype=np.float64) for c in self.candidates}
        self.channels = [c for c in CHANNELS if c in self.series and np.std(self.series[c]) > 0]
        self.derivatives = [d for d in DERIVATIVES if d in self.series]


def _scaled(unit: FloatArray, share: float, noise_ms: float) -> FloatArray:
    """``unit`` scaled so that it makes ``share`` of (its mean square + the noise's)."""
    ms = float(np.mean(unit**2))
    return np.asarray(unit * np.sqrt(share / (1.0 - share) * noise_ms / ms), dtype=np.float64)


def _effect(
    kind: str, trip: Trip, rng: np.random.Generator, share: float, noise_ms: float, avoid: str
) -> tuple[str, FloatArray]:
    """(expected name or kind, effect series)."""
    sign = rng.choice((-1.0, 1.0))
    if kind == "channel":
        name = str(rng.choice([c for c in trip.channels if c != avoid]))
        values = trip.series[name]
        if name not in PHYSICAL_ZERO:
            values = values - float(np.mean(values))
        return name, sign * _scaled(values, share, noise_ms)
    if kind == "derivative":
        name = str(rng.choice([d for d in trip.derivatives if d != avoid]))
        return name, sign * _scaled(trip.series[name], share, noise_ms)
    if kind == "gain":
        return "gain", sign * _scaled(trip.simulated, share, noise_ms)
    if kind == "offset":
        return "offset", sign * _scaled(np.ones_like(trip.simulated), share, noise_ms)
    shift = max(1, round(rng.uniform(*LAG_S) / trip.dt)) * int(sign)
    n = trip.simulated.shape[0]
    moved = trip.simulated[np.clip(np.arange(n) - shift, 0, n - 1)]
    return "lag", moved - trip.simulated


def _first(diagnosis: Any) -> tuple[str, str, tuple[str, ...]] | None:
    relevant = diagnosis.relevant
    if not relevant:
        return None
    return relevant[0].name, relevant[0].kind, relevant[0].members


def _matches(first: tuple[str, str, tuple[str, ...]] | None, expected: str) -> bool:
    """The first finding is the injected effect: by kind for gain, offset and lag; by name for
    a series, the effect's other members included (candidates that measure the same thing)."""
    if first is None:
        return False
    name, kind, members = first
    if expected in ("gain", "offset", "lag"):
        return kind == expected
    return expected == name or expected in members


def run(draws: int, controls: int, seed: int, log: Callable[[str], None]) -> dict[str, Any]:
    from pytest_hevval.scoring.diagnosis import diagnose_pair

    rng = np.random.default_rng(seed)
    tally: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    misses: list[dict[str, Any]] = []
    started = time.perf_counter()
    cases = [*([k] for k in KINDS), *([a, b] for i, a in enumerate(KINDS) for b in KINDS[i + 1 :])]
    for spec in SPECS:
        trip = Trip(spec)
        log(f"{trip.name}: {trip.simulated.shape[0]} samples, {len(trip.candidates)} candidates")
        for _ in range(draws):
            for case in [*([] for _ in range(controls)), *cases]:
                shift = int(
                    rng.integers(int(0.2 * len(trip.residual)), int(0.8 * len(trip.residual)))
                )
                noise = np.roll(trip.residual, shift)
                noise_ms = float(np.mean(noise**2))
                shares = SHARE_ONE if len(case) == 1 else SHARE_TWO
                expected: list[str] = []
                effect = np.zeros_like(noise)
                for kind in case:
                    name, series = _effect(
                        kind,
                        trip,
                        rng,
                        rng.uniform(*shares),
                        noise_ms,
                        expected[0] if expected else "",
                    )
                    expected.append(name)
                    effect += series
                found = diagnose_pair(
                    trip.evaluation,
                    trip.simulated + effect + noise,
                    trip.simulated,
                    trip.candidates,
                )
                first = _first(found)
                label = "control" if not case else "+".join(case)
                if not case:
                    wrong = first is not None
                else:
                    wrong = not any(_matches(first, e) for e in expected)
                tally[label][0] += int(not wrong)
                tally[label][1] += 1
                if wrong:
                    misses.append(
                        {"trip": trip.name, "case": label, "injected": expected, "first": first}
                    )
    elapsed = time.perf_counter() - started
    return {"tally": dict(tally), "misses": misses, "seconds": elapsed, "draws": draws}


LOADS = ("Heating Power CAN [kW]", "AirCon Power [kW]")


#: The conditions that broke real trips, each on top of the shifted real residual:
#: ``plain``: the load added; ``jitter``: the reference's driving part timed with a slowly
#: wandering delay (σ 0.2 s) against the model; ``noisy``: every offered copy of the load
#: carries its own white noise (σ a third of the load's); ``follower``: a temperature that
#: follows the load through a first-order lag (τ 120 s) is offered too; ``constant``: the
#: model's constant already covers half of the load's mean. The load is added as logged (its
#: zero is "off"), scaled to make 20–60 % of the residual's mean square; that scale is the
#: coefficient its interval must hold.
CONDITIONS = ("plain", "jitter", "noisy", "follower", "constant")
JITTER_S = 0.2
FOLLOWER_TAU_S = 120.0


def _condition(
    condition: str,
    trip: Trip,
    load: str,
    effect: FloatArray,
    noise: FloatArray,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, list[Any]]:
    """(reference, simulated, candidates) of one draw under ``condition``; ``effect`` is the
    injected load series (zeros for a control)."""
    from pytest_hevval.core.residual import Candidate

    values = trip.series[load]
    sim = trip.simulated
    candidates = list(trip.candidates)
    driving = sim
    if condition == "jitter":
        n = sim.shape[0]
        t = np.arange(n) * trip.dt
        wander = np.cumsum(rng.standard_normal(n))
        wander = np.convolve(wander - wander.mean(), np.ones(50) / 50, "same")
        delay = JITTER_S * wander / max(float(np.std(wander)), 1e-12)
        driving = np.interp(t - delay, t, sim)
    reference = driving + effect + noise
    if condition == "noisy":
        spread = float(np.std(values)) / 3.0
        candidates = [
            Candidate(c.name, c.kind, c.values + spread * rng.standard_normal(values.shape[0]))
            if abs(float(np.corrcoef(c.values, values)[0, 1])) >= 0.9
            else c
            for c in candidates
        ]
    if condition == "follower":
        a = math.exp(-trip.dt / FOLLOWER_TAU_S)
        from scipy.signal import lfilter

        follower = lfilter([1.0 - a], [1.0, -a], values - float(np.mean(values)))
        temperature = 20.0 + 4.0 * follower / max(float(np.std(follower)), 1e-12)
        candidates.append(Candidate("Follower Temperature [°C]", "channel", temperature))
    if condition == "constant":
        sim = sim + 0.5 * float(np.mean(effect))
    return reference, sim, candidates


def coverage(draws: int, controls: int, seed: int, log: Callable[[str], None]) -> dict[str, Any]:
    """Under each condition: how often a logged load, added with a known coefficient, is the
    first finding with a positive coefficient; how often its 95 % interval holds that
    coefficient; and how often a control (the same condition, no load added) gets a false
    finding (a relevant channel, derivative or declared effect)."""
    from pytest_hevval.scoring.diagnosis import diagnose_pair

    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    for spec in SPECS:
        trip = Trip(spec)
        load = max(LOADS, key=lambda c: float(np.std(trip.series.get(c, np.zeros(1)))))
        if float(np.std(trip.series[load])) < 0.1:
            log(f"{trip.name}: no load varies; skipped")
            continue
        values = trip.series[load]
        for condition in CONDITIONS:
            found = first = covered = false = 0
            widths: list[float] = []
            coefficients: list[float] = []
            for case in [*(["load"] * draws), *(["control"] * controls)]:
                n = len(trip.residual)
                noise = np.roll(trip.residual, int(rng.integers(int(0.2 * n), int(0.8 * n))))
                noise_ms = float(np.mean(noise**2))
                # The load as logged (its zero is "off"), scaled to make 20–60 % of the
                # residual's mean square: the scale is the coefficient to recover.
                if case == "load":
                    effect = _scaled(values, rng.uniform(*SHARE_ONE), noise_ms)
                    truth = float(np.mean(effect * values) / np.mean(values * values))
                else:
                    effect, truth = np.zeros_like(values), 0.0
                reference, simulated, candidates = _condition(
                    condition, trip, load, effect, noise, rng
                )
                d = diagnose_pair(trip.evaluation, reference, simulated, candidates)
                if case == "control":
                    false += int(any(e.kind not in ("gain", "offset", "lag") for e in d.relevant))
                    continue
                top = _first(d)
                # The wandering delay is an effect too (the model is late or early): as for two
                # injected effects, the first finding is right when it is one of the two.
                timing = condition == "jitter" and _matches(top, "lag")
                first += int(timing or (_matches(top, load) and d.relevant[0].coefficient > 0))
                effect_found = next(
                    (e for e in d.effects if load == e.name or load in e.members), None
                )
                if effect_found is None or not effect_found.significant:
                    continue
                found += 1
                low, high = effect_found.interval
                covered += int(low <= truth <= high)
                widths.append((high - low) / truth)
                coefficients.append(effect_found.coefficient / truth)
            log(
                f"{trip.name} {condition}: {first}/{draws} first, {covered}/{found} covered, "
                f"{false}/{controls} controls false"
            )
            rows.append(
                {
                    "trip": trip.name,
                    "condition": condition,
                    "load": load,
                    "draws": draws,
                    "first": first,
                    "found": found,
                    "covered": covered,
                    "controls": controls,
                    "false": false,
                    "median_width": float(np.median(widths)) if widths else None,
                    "median_ratio": float(np.median(coefficients)) if coefficients else None,
                }
            )
    return {"rows": rows, "seconds": time.perf_counter() - started}


def coverage_table(result: dict[str, Any]) -> str:
    lines = [
        "| trip | condition | load | draws | first finding, positive | found significant "
        "| interval holds the coefficient | median found / true | median width / true "
        "| controls with a false finding |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]

    def ratio(value: float | None) -> str:
        return f"{value:.2f}" if value is not None else "–"

    for r in result["rows"]:
        share = f"{100 * r['covered'] / r['found']:.0f} %" if r["found"] else "–"
        lines.append(
            f"| {r['trip']} | {r['condition']} | {r['load']} | {r['draws']} | {r['first']} "
            f"| {r['found']} | {share} | {ratio(r['median_ratio'])} "
            f"| {ratio(r['median_width'])} | {r['false']}/{r['controls']} |"
        )
    for condition in CONDITIONS:
        rows = [r for r in result["rows"] if r["condition"] == condition]
        draws = sum(r["draws"] for r in rows)
        first = sum(r["first"] for r in rows)
        found = sum(r["found"] for r in rows)
        covered = sum(r["covered"] for r in rows)
        controls = sum(r["controls"] for r in rows)
        false = sum(r["false"] for r in rows)
        lines.append(
            f"| **all** | **{condition}** | | {draws} | **{100 * first / max(draws, 1):.0f} %** "
            f"| {found} | **{100 * covered / max(found, 1):.0f} %** | | "
            f"| **{100 * false / max(controls, 1):.0f} %** ({false}/{controls}) |"
        )
    return "\n".join(lines)


def table(result: dict[str, Any]) -> str:
    rows = [
        "| injected | diagnoses | first finding right | false finding |",
        "|---|---:|---:|---:|",
    ]
    singles = [k for k in KINDS]
    pairs = [k for k in result["tally"] if "+" in k]
    total_right = total = 0
    for label in [*singles, *pairs]:
        right, n = result["tally"][label]
        total_right += right
        total += n
        rows.append(f"| {label} | {n} | {100 * right / n:.0f} % | |")
    rows.append(f"| **all effects** | {total} | **{100 * total_right / total:.1f} %** | |")
    ok, n = result["tally"]["control"]
    rows.append(f"| control (none) | {n} | | **{100 * (n - ok) / n:.1f} %** |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=20, help="draws per case and trip")
    parser.add_argument("--controls", type=int, default=5, help="controls per draw and trip")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--misses", action="store_true", help="list every wrong first finding")
    parser.add_argument(
        "--coverage", action="store_true", help="check the intervals of a real load instead"
    )
    args = parser.parse_args()
    # The example's model package is imported from the example folder, as its specs expect.
    os.chdir(EXAMPLE)
    sys.path.insert(0, str(EXAMPLE))

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    if args.coverage:
        checked = coverage(args.draws, args.controls, args.seed, log)
        print(coverage_table(checked))
        print(f"\n{args.draws} draws per trip in {checked['seconds']:.0f} s (seed {args.seed})")
        if args.json:
            args.json.write_text(json.dumps(checked, indent=1), encoding="utf-8")
        return
    result = run(args.draws, args.controls, args.seed, log)
    print(table(result))
    print(
        f"\n{sum(n for _, n in result['tally'].values())} diagnoses in "
        f"{result['seconds']:.0f} s (draws {args.draws}, controls {args.controls}, "
        f"seed {args.seed})"
    )
    if args.misses:
        for miss in result["misses"]:
            print(miss)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()
