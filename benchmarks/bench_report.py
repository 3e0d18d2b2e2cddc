"""Time report generation: synthetic results, the example project's results, its whole run.

Run from the project root::

    python benchmarks/bench_report.py                       # every part (about 10 minutes)
    python benchmarks/bench_report.py --part synthetic      # 600 demo signals, html + json + md
    python benchmarks/bench_report.py --part synthetic --signals 60  # quicker
    python benchmarks/bench_report.py --part example        # write_reports on the example
    python benchmarks/bench_report.py --part runs --rounds 5  # the example with and without HTML

What each part measures, and where that cost is paid:

* ``synthetic``: ``figure_data`` for one signal of one hour at 100 Hz (360,000 samples), paid
  by the engine once per signal wherever the traces live (an xdist worker, a Dask node); then
  ``write_reports`` for many demo signals, paid once by the controller from result dicts only.
* ``example``: ``write_reports`` of the HTML report on the example project's own results (as
  the report receives them, diagnoses included), the size of the page and of its parts.
* ``runs``: ``pytest --hevval`` in ``example_project/`` without and with
  ``--hevval-report=html``, alternating run by run so that both see the same load, each with
  an empty history folder of its own (the history is not what is measured here); medians of
  the wall and CPU times and their ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from _env import timed_run

from pytest_hevval.report import figure_data, write_reports

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "example_project"
sys.path.insert(0, str(ROOT))
from tests.demo_results import demo_results  # noqa: E402


def _results(signals: int) -> list[dict[str, Any]]:
    """Demo specs (at most 10) holding exactly ``signals`` signals between them."""
    per_set = 7  # signals in one demo signal set
    specs = max(1, min(10, signals // per_set))
    sets = -(-signals // (specs * per_set))
    results = demo_results(specs=specs, sets_per_spec=sets, duration_s=600.0, rate_hz=10.0)
    remaining = signals
    for spec in results:
        keep = min(len(spec["signals"]), remaining)
        spec["signals"] = spec["signals"][:keep]
        remaining -= keep
    return [spec for spec in results if spec["signals"]]


def _synthetic(signals: int, formats: set[str]) -> None:
    rng = np.random.default_rng(0)
    n = 360_000
    ref = np.cumsum(rng.normal(0.0, 1.0, n))
    sim = np.roll(ref, 20) + rng.normal(0.0, 0.5, n)
    figure_data(ref[:1000], sim[:1000], dt=0.01, start_s=0.0, max_lag=10)
    timings = {}
    for max_lag in (500, 36_000):
        runs = []
        for _ in range(7):
            start = time.perf_counter()
            figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=max_lag)
            runs.append(time.perf_counter() - start)
        timings[max_lag] = statistics.median(runs)
    print(
        f"figure_data, 360,000 samples: median {timings[500] * 1e3:.1f} ms (max_lag 5 s), "
        f"{timings[36_000] * 1e3:.1f} ms (max_lag 360 s)"
    )

    results = _results(signals)
    count = sum(len(spec["signals"]) for spec in results)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        paths = write_reports(results, formats, Path(tmp), title="benchmark")
        elapsed = time.perf_counter() - start
        sizes = ", ".join(f"{p.name} {p.stat().st_size / 1e6:.1f} MB" for p in paths)
    print(f"write_reports, {count} signals in {len(results)} specs: {elapsed:.1f} s ({sizes})")


def _pytest(
    report_dir: Path | None, history_dir: Path, formats: str = "html"
) -> tuple[float, float]:
    """Wall and CPU time (user + system) of one ``pytest --hevval`` run of the example project.

    The CPU time is less sensitive than the wall time to other work on a shared machine.
    """
    command = [
        sys.executable,
        "-m",
        "pytest",
        "--hevval",
        "-p",
        "no:cacheprovider",
        "-q",
        f"--hevval-history-dir={history_dir}",
    ]
    if report_dir is not None:
        command += [f"--hevval-report={formats}", f"--hevval-report-dir={report_dir}"]
    elapsed, cpu, done = timed_run(command, EXAMPLE)
    # The example fails some items on purpose (exit 1); anything else is a broken run.
    if done.returncode not in (0, 1):
        raise SystemExit(f"pytest exited {done.returncode}:\n{done.stdout[-3000:]}{done.stderr}")
    return elapsed, cpu


def _parts(page: str) -> dict[str, int]:
    """Bytes of the page by what they draw."""
    parts = {
        "signal plots": r'<svg class="hv-plot".*?</svg>',
        "glyph plots": r'<svg class="hv-glyph".*?</svg>',
        "local plots": r'<svg class="hv-local".*?</svg>',
        "bitmaps": r"data:image/[a-z]+;base64,[A-Za-z0-9+/=]+",
    }
    sizes = {
        name: sum(len(m.encode()) for m in re.findall(pattern, page, re.S))
        for name, pattern in parts.items()
    }
    sizes["rest"] = len(page.encode()) - sum(sizes.values())
    return sizes


def _example(repeat: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _pytest(folder / "report", folder / "history", formats="html,json")
        specs = json.loads((folder / "report" / "report.json").read_text("utf-8"))["specs"]
        count = sum(len(spec["signals"]) for spec in specs)
        write_reports(specs, {"html"}, folder / "warm", title="benchmark")  # imports
        runs = []
        for _ in range(repeat):
            start = time.perf_counter()
            (page_path,) = write_reports(specs, {"html"}, folder / "html", title="benchmark")
            runs.append(time.perf_counter() - start)
        page = page_path.read_text("utf-8")
        json_size = (folder / "report" / "report.json").stat().st_size
    parts = _stages(specs)
    print(
        f"write_reports html, the example ({count} signals in {len(specs)} specs): median "
        f"{statistics.median(runs):.2f} s of {repeat} (min {min(runs):.2f} s); "
        f"report.html {len(page.encode()) / 1e6:.2f} MB, report.json {json_size / 1e6:.2f} MB"
    )
    rest = statistics.median(runs) - sum(parts.values())
    print(
        "  of which: "
        + ", ".join(f"{name} {seconds:.2f} s" for name, seconds in parts.items())
        + f", the rest (views, template, writing) {rest:.2f} s"
    )
    print(
        "  page parts: "
        + ", ".join(f"{name} {size / 1e6:.2f} MB" for name, size in _parts(page).items())
    )


def _stages(specs: list[dict[str, Any]]) -> dict[str, float]:
    """Median seconds of the plots of one page, drawn apart from the page (3 repetitions)."""
    from pytest_hevval.report import plots, svg

    def glyphs() -> None:
        for spec in specs:
            plots.glyph_plot(spec)

    def signals() -> None:
        share = svg.PathShare()
        for i, spec in enumerate(specs):
            for j, signal in enumerate(spec["signals"]):
                svg.signal_svg(signal, f"{i}-{j}", share)

    out = {}
    for name, stage in (("glyph plots", glyphs), ("signal plots", signals)):
        runs = []
        for _ in range(3):
            start = time.perf_counter()
            stage()
            runs.append(time.perf_counter() - start)
        out[name] = statistics.median(runs)
    return out


def _runs(rounds: int) -> None:
    times: dict[str, list[tuple[float, float]]] = {"without": [], "html": []}
    with tempfile.TemporaryDirectory() as tmp:
        _pytest(None, Path(tmp))  # warms the file cache and the .pyc files
    for k in range(rounds):
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            # Alternate which goes first, so that neither always runs on a warmer machine.
            for kind in ("without", "html") if k % 2 == 0 else ("html", "without"):
                report = folder / "report" if kind == "html" else None
                times[kind].append(_pytest(report, folder / f"history-{kind}"))
        (wall_a, cpu_a), (wall_b, cpu_b) = times["without"][-1], times["html"][-1]
        print(
            f"  round {k + 1}: without {wall_a:.2f} s (cpu {cpu_a:.2f} s), with html "
            f"{wall_b:.2f} s (cpu {cpu_b:.2f} s); load {os.getloadavg()[0]:.2f}"
        )
    for what, index in (("wall", 0), ("cpu", 1)):
        a = [t[index] for t in times["without"]]
        b = [t[index] for t in times["html"]]
        paired = statistics.median(y / x for x, y in zip(a, b, strict=True))
        print(
            f"example run, {rounds} rounds, {what} time: median without "
            f"{statistics.median(a):.2f} s, with --hevval-report=html {statistics.median(b):.2f} s;"
            f" ratio of medians {statistics.median(b) / statistics.median(a):.3f}, median ratio "
            f"within a round {paired:.3f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("synthetic", "example", "runs", "all"), default="all")
    parser.add_argument("--signals", type=int, default=600, help="synthetic signals")
    parser.add_argument("--formats", default="html,json,md", help="synthetic report formats")
    parser.add_argument("--repeat", type=int, default=5, help="write_reports on the example")
    parser.add_argument("--rounds", type=int, default=5, help="example runs of each kind")
    args = parser.parse_args()
    if args.part in ("synthetic", "all"):
        _synthetic(args.signals, {f.strip() for f in args.formats.split(",")})
    if args.part in ("example", "all"):
        _example(args.repeat)
    if args.part in ("runs", "all"):
        _runs(args.rounds)


if __name__ == "__main__":
    main()
