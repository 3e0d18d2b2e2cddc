"""Model runtime under noise: no false alarm over repeated identical runs, and a model made
three times slower caught by the ``runtime`` gate and by ``hevval compare``'s rule.

Run from the project root (under ``nice`` on a shared machine)::

    nice python benchmarks/bench_runtime_noise.py              # ten identical runs, then 3× slower
    nice python benchmarks/bench_runtime_noise.py --runs 3     # quick
    nice python benchmarks/bench_runtime_noise.py --load 2     # two busy processes beside it

The i3 campaign of the example project (``specs/i3-campaign-v2.hevval.yaml``, every trip) is
scored as ``pytest --hevval`` scores it, with ``runtime: {repeat: 3}`` (the model called three
times per trip, ``--repeat``; intervals off, since they do not touch the model). A first run is
the baseline; its fastest calls set the gate (``min_realtime_factor`` on the default clock,
CPU time) at the lowest real-time factor of a trip divided by ``--allowance`` (2). Then ``--runs``
identical runs, each compared with the baseline by
:func:`pytest_hevval.history.runtime_changes.runtime_changes` and judged by the gate: every alarm
there is a false one. Last, the same campaign with a model that runs the EV model three times
per call (three times the work): it must fail the gate (on at least one trip: the gate is the
campaign's) and be a runtime regression. ``--load N`` starts
N processes that spin on the CPU for the whole benchmark, to load the machine further; the
load average is printed with each run.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import tempfile
import time
from pathlib import Path

from pytest_hevval.results.recorded import RecordedSpec

HERE = Path(__file__).resolve().parent
EXAMPLE = HERE.parent / "example_project"
SPEC = EXAMPLE / "specs" / "i3-campaign-v2.hevval.yaml"
MODEL = 'callable: "models.ev:simulate"'
SLOW_MODEL = """\
from models import ev


def simulate(frame, **params):
    # Three times the EV model's work per call: the first two results are thrown away.
    for _ in range(2):
        ev.simulate(frame, **params)
    return ev.simulate(frame, **params)
"""


def _spin() -> None:
    while True:
        pass


def _recorded(results: list[dict[str, object]]) -> list[RecordedSpec]:
    return [RecordedSpec.from_json(result) for result in results]


def _campaign(text: str) -> list[dict[str, object]]:
    from pytest_hevval.scoring.run import RunOptions, run_specs
    from pytest_hevval.spec.load import parse_spec_text

    spec = parse_spec_text(text, SPEC)
    evaluations = run_specs(
        list(spec.per_recording()), RunOptions(rootdir=EXAMPLE, intervals=False)
    )
    return [e.result.to_dict() for e in evaluations]


def _with_runtime(text: str, runtime: str, model: str = MODEL) -> str:
    return text.replace(MODEL, model).replace("\nsets:\n", f"\nruntime: {runtime}\nsets:\n", 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10, help="identical runs after the baseline")
    parser.add_argument("--load", type=int, default=0, help="busy processes beside the runs")
    parser.add_argument(
        "--repeat", type=int, default=3, help="model calls per trip (runtime.repeat)"
    )
    parser.add_argument(
        "--allowance",
        type=float,
        default=2.0,
        help="the gate: the lowest baseline real-time factor of a trip divided by this",
    )
    args = parser.parse_args()
    from pytest_hevval.history.runtime_changes import runtime_changes
    from pytest_hevval.results.runtime import ModelRuntime

    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(args.load)]
    for spinner in spinners:
        spinner.start()
    os.chdir(EXAMPLE)
    sys.path.insert(0, str(EXAMPLE))
    text = SPEC.read_text(encoding="utf-8")

    def best_factors(results: list[dict[str, object]]) -> list[float]:
        """Each trip's real-time factor over its fastest call."""
        return [
            ModelRuntime.from_dict(r["runtime"]).best_realtime_factor("cpu")  # type: ignore[arg-type]
            for r in results
        ]

    def gate_failures(results: list[dict[str, object]]) -> int:
        return sum(1 for r in results if r["runtime"]["passed"] is False)  # type: ignore[index]

    started = time.perf_counter()
    baseline = _campaign(_with_runtime(text, f"{{repeat: {args.repeat}}}"))
    factors = best_factors(baseline)
    gate = f"{{repeat: {args.repeat}, min_realtime_factor: {min(factors) / args.allowance:.0f}}}"
    print(
        f"baseline: {len(baseline)} trips, real-time factors (cpu) {min(factors):.0f} to "
        f"{max(factors):.0f} (fastest calls); gate runtime: {gate}; "
        f"load {os.getloadavg()[0]:.1f}"
    )
    alarms = 0
    failed_gates = 0
    for run in range(1, args.runs + 1):
        results = _campaign(_with_runtime(text, gate))
        [change] = runtime_changes(_recorded(baseline), _recorded(results))
        failures = gate_failures(results)
        alarms += change.regression
        failed_gates += failures
        print(
            f"identical run {run:2d}: ×{change.ratio:.2f} of the baseline's CPU (fastest calls), "
            f"regression {change.regression}, gate failures {failures}/{len(results)}; "
            f"load {os.getloadavg()[0]:.1f}"
        )
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, "slow_ev.py").write_text(SLOW_MODEL, encoding="utf-8")
        sys.path.insert(0, folder)
        slow = _campaign(_with_runtime(text, gate, 'callable: "slow_ev:simulate"'))
    [change] = runtime_changes(_recorded(baseline), _recorded(slow))
    print(
        f"3× slower model: ×{change.ratio:.2f} of the baseline's CPU (fastest calls), "
        f"real-time factor (cpu) {min(best_factors(slow)):.0f} to {max(best_factors(slow)):.0f}, "
        f"regression {change.regression}, gate failures "
        f"{gate_failures(slow)}/{len(slow)}; load {os.getloadavg()[0]:.1f}"
    )
    print(
        f"false alarms over {args.runs} identical runs: {alarms} runtime regressions, "
        f"{failed_gates} gate failures ({time.perf_counter() - started:.0f} s in all)"
    )
    for spinner in spinners:
        spinner.terminate()
    # The gate is the campaign's: it fails when any trip misses it.
    caught = change.regression and gate_failures(slow) > 0
    return 0 if caught and alarms == 0 and failed_gates == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
