"""History benchmark: what a long validation history costs a run.

Run from the project root::

    python benchmarks/bench_history.py --part history            # the history part alone
    python benchmarks/bench_history.py --part pytest             # the example project, whole
    python benchmarks/bench_history.py                           # both

The records are synthetic but realistic: copies of a record the example project wrote (23 specs,
137 signals, about 360 KB), each with its own model version, start time (three runs a day,
oldest first) and slightly different Φ and λ. The seed record comes from one run of
``pytest --hevval`` in ``example_project/`` and is kept in ``benchmarks/.data/history/`` (not
tracked); ``--seed PATH`` uses another record, ``--fresh-seed`` runs the example again.

``--part history``
    What a run does that depends on its history, step by step, on folders of ``--records``
    records, in one process, ``--repeat`` runs each: ``Publisher.start`` (the baseline of
    ``--hevval-compare=latest``, read), ``Publisher._panels`` (each signal's trend for the
    HTML report), the trend plots the report draws from them (``report.svg.history_svg``, one
    per signal that has a trend; the rest of the report does not depend on the history, but
    for the page growing by about 6 KB per trend) and
    ``Publisher._record`` (its own record, written, and added to the index).
    Each run adds a record, so the folder grows by one per run, as in use; the empty one is
    emptied again. Measured with the index present (every run but the first) and, for the
    sizes in ``--cold``, once without it (the run that builds it by reading every record, as
    after a fresh clone). ``--fresh-clone`` adds ``--repeat`` runs that each find the records
    without an index, as every CI job on a fresh clone does. ``--full-read`` also times
    ``HistoryStore.entries()``, the full read every run paid before the index.
``--part trends``
    ``HistoryStore.trends`` on ``--pytest-records`` records without an index, as on a fresh
    clone: the run's own signals (the newest records parsed), then with one more spec that no
    record holds (the older records searched for its paths, not parsed).
``--part pytest``
    ``pytest --hevval --hevval-report=html`` on the example project with an empty history and
    with ``--pytest-records`` records, alternating run by run (the order swaps each round), in
    child processes. The history folder and the report go to temporary folders
    (``--hevval-history-dir``, ``--hevval-report-dir``); the example project is not written
    to. The large history is run once first to build its index (timed and printed apart);
    each run adds its own record, so the large history grows by one per round, as in use.
    With ``--fresh-clone`` the index is removed before each run on the large history, as on
    a fresh clone.
    Wall time and CPU time (user + system of the child) are both printed: on a shared machine
    the CPU time is the steadier of the two. The whole example scores for half a minute, and
    a shared machine varies it by seconds; ``--select hwfet`` runs one spec of it (a few
    seconds), which pays the same history costs (the folder listed, the index read for the
    trends, the record added to it; only the plots of three trends instead of 137) with far
    less noise around them.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
from _env import timed_run

from pytest_hevval.files import read_json
from pytest_hevval.history import HistoryStore, format_utc, migrate_record, slugify
from pytest_hevval.history.store import record_text
from pytest_hevval.publish import Publication, Publisher, PublishOptions
from pytest_hevval.report.svg import history_svg
from pytest_hevval.results.spec_result import SpecResult

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "example_project"
SEED_DIR = Path(__file__).resolve().parent / ".data" / "history"
# Every run is recorded, as in CI (a local run records nothing unless asked).
PYTEST = [
    sys.executable,
    "-m",
    "pytest",
    "--hevval",
    "--hevval-history",
    "-q",
    "-p",
    "no:cacheprovider",
]
START = datetime(2025, 1, 1, tzinfo=timezone.utc)


def _machine() -> str:
    """Load average and CPU pressure: the machine is shared, so every section says how busy."""
    parts = ["load " + " ".join(f"{x:.2f}" for x in os.getloadavg())]
    with contextlib.suppress(OSError), open("/proc/pressure/cpu") as pressure:
        parts.append("cpu pressure " + " ".join(pressure.readline().split()[1:3]))
    return ", ".join(parts)


def _run_example(history: Path, report: Path, select: str | None = None) -> tuple[float, float]:
    """One ``pytest --hevval --hevval-report=html`` of the example project (``-k select`` when
    given): its wall time and its CPU time (user + system, the child and everything it waited
    for)."""
    command = [
        *PYTEST,
        "--hevval-report=html",
        f"--hevval-history-dir={history}",
        f"--hevval-report-dir={report}",
        *(["-k", select] if select else []),
    ]
    elapsed, cpu, done = timed_run(command, EXAMPLE)
    # The example fails some items on purpose (exit 1); anything else is a broken run.
    if done.returncode not in (0, 1) or "report: " not in done.stdout:
        sys.exit(f"the example run failed ({done.returncode}):\n{done.stdout[-3000:]}")
    return elapsed, cpu


def _seed(path: Path | None, fresh: bool) -> dict[str, Any]:
    """A real record of the example project, validated."""
    if path is None:
        found = sorted(SEED_DIR.glob("*.json"))
        if fresh or not found:
            print("recording the example project once for a seed record …", flush=True)
            shutil.rmtree(SEED_DIR, ignore_errors=True)
            with tempfile.TemporaryDirectory() as tmp:
                _run_example(SEED_DIR, Path(tmp))
            found = sorted(SEED_DIR.glob("*.json"))
        path = found[-1]
    record = migrate_record(read_json(path), file=str(path))
    return record


def _vary(value: Any, rng: np.random.Generator) -> Any:
    if not isinstance(value, float):
        return value
    return float(min(1.0, max(0.0, value + rng.normal(0.0, 0.005))))


def _synthetic(seed: dict[str, Any], index: int, rng: np.random.Generator) -> dict[str, Any]:
    """The seed as run ``index``: its own version and time, Φ and λ a little different."""
    specs = []
    for spec in seed["specs"]:
        signals = [
            {**signal, "lambdas": {k: _vary(v, rng) for k, v in signal["lambdas"].items()}}
            for signal in spec["signals"]
        ]
        specs.append({**spec, "phi": _vary(spec["phi"], rng), "signals": signals})
    version = f"v0.{index // 40}-{index % 40}-g{uuid.UUID(int=index).hex[-7:]}"
    started = START + timedelta(hours=8 * index, seconds=float(rng.uniform(0, 600)))
    return {**seed, "model_version": version, "started_utc": format_utc(started), "specs": specs}


def _fill(folder: Path, seed: dict[str, Any], count: int) -> None:
    """``count`` synthetic records named as the store names them (written plainly: setting up
    is not what is measured, and a thousand fsyncs would only slow it down)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(count)
    for i in range(count):
        record = _synthetic(seed, i, rng)
        stamp = datetime.fromisoformat(record["started_utc"][:-1]).strftime("%Y%m%dT%H%M%S.%fZ")
        name = f"{stamp}_{slugify(record['model_version'])}_{uuid.uuid4().hex[:8]}.json"
        (folder / name).write_text(record_text(record), encoding="utf-8")


def _publisher(history: Path, root: Path) -> Publisher:
    options = PublishOptions(
        rootdir=root,
        report="html",
        report_dir=root / "report",
        history_dir=history,
        model_version="bench",
        compare="latest",
    )
    return Publisher(options)


_STEPS = ("start", "decorate", "plots", "record")


def _history_part(
    publisher: Callable[[], Publisher], results: list[dict[str, Any]]
) -> tuple[dict[str, tuple[float, float]], int]:
    """What a run does that depends on its history: the baseline (start), the trends beside
    each signal (decorate), the trend plots the HTML report draws from them (plots) and its own
    record, added to the index (record). (wall, CPU) seconds by step, and the number of trend
    points drawn."""
    run = publisher()
    typed = [SpecResult.from_dict(spec) for spec in results]
    spent: dict[str, tuple[float, float]] = {}
    panels = None
    points = 0
    for step in _STEPS:
        wall, cpu = time.perf_counter(), time.process_time()
        if step == "start":
            run.start()
        elif step == "decorate":
            panels = run._panels(typed, {})
        elif step == "plots":
            assert panels is not None
            for result in typed:
                for signal in result.signals:
                    history = panels.history(result, signal)
                    if history:
                        history_svg(history)
                        points += len(history)
        else:
            out = Publication()
            run._record(lambda: results, run.acceptance([]), out)
            if out.failed:
                sys.exit(f"recording failed: {out.notes}")
        spent[step] = (time.perf_counter() - wall, time.process_time() - cpu)
    return spent, points


def _row(label: str, count: int, runs: list[dict[str, tuple[float, float]]], points: int) -> str:
    def ms(step: str | None, which: int) -> float:
        values = [
            sum(v[which] for v in run.values()) if step is None else run[step][which]
            for run in runs
        ]
        return statistics.median(values) * 1e3

    cells = [f"{ms(step, 0):,.0f} ms" for step in (*_STEPS, None)]
    return (
        f"| {count:,} | {label} | " + " | ".join(cells) + f" | {ms(None, 1):,.0f} ms | {points:,} |"
    )


def history_part(args: argparse.Namespace, seed: dict[str, Any]) -> None:
    results = seed["specs"]
    print(f"\n## history part alone: start, decorate, plots, record ({_machine()})")
    print(f"medians of {args.repeat} runs each; wall time, and CPU time of the total")
    print("| records | index | start | decorate | plots | record | total | total CPU | points |")
    print("|---|---|---|---|---|---|---|---|---|", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for count in args.records:
            folder = root / f"h{count}"
            _fill(folder, seed, count)

            def publisher(folder: Path = folder) -> Publisher:
                return _publisher(folder, root)

            if count and count in args.cold:
                spent, points = _history_part(publisher, results)
                print(_row("missing", count, [spent], points), flush=True)
            if count and args.fresh_clone:
                fresh = []
                for _ in range(args.repeat):
                    # As in a fresh clone: the records, and no index (it is never committed).
                    shutil.rmtree(folder / ".index", ignore_errors=True)
                    spent, points = _history_part(publisher, results)
                    fresh.append(spent)
                print(_row("none: fresh clone", count, fresh, points), flush=True)
            runs = []
            for _ in range(args.repeat):
                spent, points = _history_part(publisher, results)
                runs.append(spent)
                if not count:  # an empty history stays empty; the others grow as in use
                    for path in folder.glob("*.json"):
                        path.unlink()
            print(_row("present" if count else "–", count, runs, points), flush=True)
            if args.full_read and count:
                t0 = time.perf_counter()
                HistoryStore(folder).entries()
                print(
                    f"|   | full read, as every run did before | | | | | "
                    f"{time.perf_counter() - t0:,.1f} s | | |",
                    flush=True,
                )
            shutil.rmtree(folder)


def trends_part(args: argparse.Namespace, seed: dict[str, Any]) -> None:
    """``HistoryStore.trends`` of the run's own signals on ``--pytest-records`` records without
    an index (a fresh clone), and the same with one spec no record holds (one a pull request
    adds), ``--repeat`` times each."""
    keys = [(spec["spec"], signal["path"]) for spec in seed["specs"] for signal in spec["signals"]]
    count = args.pytest_records
    print(f"\n## trends of a run on {count:,} records without an index ({_machine()})")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "history"
        _fill(folder, seed, count)
        for label, wanted in (
            ("the run's own signals", keys),
            ("and a spec no record holds", [*keys, ("new.hevval.yaml", "signal")]),
        ):
            for _ in range(args.repeat):
                wall, cpu = time.perf_counter(), time.process_time()
                HistoryStore(folder).trends(wanted)
                print(
                    f"{label}: {time.perf_counter() - wall:.2f} s, "
                    f"CPU {time.process_time() - cpu:.2f} s",
                    flush=True,
                )
        if (folder / ".index").exists():
            sys.exit("the trends of the newest records built the whole index")


def pytest_part(args: argparse.Namespace, seed: dict[str, Any]) -> None:
    count = args.pytest_records
    select = f" -k {args.select!r}" if args.select else ""
    print(
        f"\n## pytest --hevval --hevval-report=html{select} on example_project: 0 against "
        f"{count:,} records, {args.rounds} rounds ({_machine()})",
        flush=True,
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        large = root / "large"
        _fill(large, seed, count)
        wall, cpu = _run_example(large, root / "report", args.select)
        print(
            f"first run on {count:,} records (no index yet): {wall:.1f} s, CPU {cpu:.1f} s",
            flush=True,
        )
        index = large / ".index"
        times: dict[int, list[tuple[float, float]]] = {0: [], count: []}
        for round_index in range(args.rounds):
            order = (0, count) if round_index % 2 == 0 else (count, 0)
            for size in order:
                folder = large if size else root / f"empty{round_index}"
                if size and args.fresh_clone:
                    shutil.rmtree(index, ignore_errors=True)  # as in a fresh clone
                times[size].append(_run_example(folder, root / "report", args.select))
            (w0, c0), (w1, c1) = times[0][-1], times[count][-1]
            print(
                f"round {round_index + 1}: 0 records {w0:.1f} s (CPU {c0:.1f} s), "
                f"{count:,} records {w1:.1f} s (CPU {c1:.1f} s); {_machine()}",
                flush=True,
            )
        for which, label in ((0, "wall"), (1, "CPU")):
            empty = [t[which] for t in times[0]]
            large_ = [t[which] for t in times[count]]
            paired = [b - a for a, b in zip(empty, large_, strict=True)]
            print(
                f"{label}: median 0 records {statistics.median(empty):.2f} s, "
                f"{count:,} records {statistics.median(large_):.2f} s, difference of the "
                f"medians {statistics.median(large_) - statistics.median(empty):+.2f} s, "
                f"median of the paired differences {statistics.median(paired):+.2f} s"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["history", "pytest", "trends", "all"], default="all")
    parser.add_argument("--records", type=int, nargs="+", default=[0, 1000, 5000])
    parser.add_argument("--cold", type=int, nargs="*", default=[1000])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--full-read", action="store_true")
    parser.add_argument(
        "--fresh-clone",
        action="store_true",
        help="also (history part) or only (pytest part) run the records without an index, "
        "as a fresh clone has them",
    )
    parser.add_argument("--pytest-records", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--select", metavar="EXPR", help="run only the example's items -k EXPR selects"
    )
    parser.add_argument("--seed", type=Path, help="a history record to copy")
    parser.add_argument("--fresh-seed", action="store_true")
    args = parser.parse_args()

    seed = _seed(args.seed, args.fresh_seed)
    signals = sum(len(spec["signals"]) for spec in seed["specs"])
    print(f"seed record: {len(seed['specs'])} specs, {signals} signals")
    if args.part in ("history", "all"):
        history_part(args, seed)
    if args.part in ("trends", "all"):
        trends_part(args, seed)
    if args.part in ("pytest", "all"):
        pytest_part(args, seed)


if __name__ == "__main__":
    main()
