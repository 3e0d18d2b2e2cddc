"""Campaign benchmark: what scoring recordings as one campaign costs over scoring them one by one.

Run from the project root::

    python benchmarks/bench_campaign.py --recordings 10 --repeat 1    # quick
    python benchmarks/bench_campaign.py                              # 100 recordings, 3 repeats
    python benchmarks/bench_campaign.py --part spread --counts 50,100,200 --repeat 3
    python benchmarks/bench_campaign.py --part spread --counts 20,40 --rate 100   # 60,000 samples

The data: ``--recordings`` recordings of 10 min at 10 Hz (6,000 samples) with 20 channels, and a
callable model that reproduces each channel with a lag, a gain and noise. Two ways to score the
same recordings, side by side in one process, alternating within each repetition:

``single``
    one spec file per recording (``reference: {path: data/rec007.parquet}``);
``campaign``
    one spec over all of them (``reference: {path: data/rec*.parquet}``): the same scoring plus
    the campaign's own work, each recording's distribution of u for u-pooling, then the verdict.

Both run the model once per recording and read each file once. The ratio campaign / single is
the campaign's overhead. Last, one signal's u distribution (6,000 samples) computed sample by
sample (``u_distribution(u_values(...))``) against the engine's ``u_distribution_of``. Data
files are generated once into ``benchmarks/.data/campaign/`` (not tracked) and reused.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from _env import timed_run

HERE = Path(__file__).resolve().parent
ROOT = HERE / ".data" / "campaign"
RATE_HZ = 10.0
SECONDS = 600.0
CHANNELS = 20

MODEL = """\
import numpy as np
import pandas as pd


def run(frame, lag=3, gain=1.01):
    out = {"time": frame["time"]}
    rng = np.random.default_rng(len(frame))
    for name in frame.columns:
        if name != "time":
            values = np.roll(frame[name].to_numpy(), lag) * gain
            out[name] = values + rng.normal(0.0, 0.2, values.size)
    return pd.DataFrame(out)
"""


def _columns() -> list[str]:
    return [f"c{i:02d}" for i in range(CHANNELS)]


def _recording(index: int) -> pd.DataFrame:
    rng = np.random.default_rng(index)
    t = np.arange(int(SECONDS * RATE_HZ)) / RATE_HZ
    data: dict[str, np.ndarray] = {"time": t}
    for name in _columns():
        freqs = rng.uniform(0.002, 0.2, 3)
        phases = rng.uniform(0, 2 * np.pi, 3)
        wave = sum(np.sin(2 * np.pi * f * t + p) for f, p in zip(freqs, phases, strict=True))
        data[name] = 10.0 * wave + np.cumsum(rng.normal(0.0, 0.05, t.size))
    return pd.DataFrame(data)


def _sets() -> str:
    lines = ["sets:"]
    names = _columns()
    for start in range(0, len(names), 5):
        parent, *children = names[start : start + 5]
        lines.append(f"  - signal: {parent}")
        lines.append("    children:")
        lines.extend(f"      - {{signal: {child}}}" for child in children)
    return "\n".join(lines) + "\n"


def prepare(count: int) -> tuple[list[Path], Path]:
    """Write the recordings, the model and both kinds of spec; return (single specs, campaign)."""
    data = ROOT / "data"
    data.mkdir(parents=True, exist_ok=True)
    (ROOT / "campaign_bench_model.py").write_text(MODEL)
    head = (
        "model: {callable: 'campaign_bench_model:run'}\n"
        "alignment: {max_lag_s: 2}\n"
        "thresholds: {mae: 0.9}\n"
        "min_phi: 0.8\n"
    )
    singles = []
    for index in range(count):
        target = data / f"rec{index:03d}.parquet"
        if not target.exists():
            _recording(index).to_parquet(target, index=False)
        spec = ROOT / "single" / f"rec{index:03d}.hevval.yaml"
        spec.parent.mkdir(exist_ok=True)
        spec.write_text(f"reference: {{path: ../data/rec{index:03d}.parquet}}\n" + head + _sets())
        singles.append(spec)
    for extra in sorted(data.glob("rec*.parquet"))[count:]:
        extra.unlink()
    campaign = ROOT / "campaign.hevval.yaml"
    campaign.write_text(
        "reference: {path: data/rec*.parquet}\ncampaign: {min_pass_rate: 0.5}\n" + head + _sets()
    )
    return singles, campaign


def prepare_exported(count: int) -> Path:
    """The recordings of :func:`prepare` with the model's runs exported to one Parquet file
    each (``sim/rec007.parquet``), as a Simulink or Dymola batch leaves them, and a campaign
    spec over both (``model: {path: sim/{id}.parquet}``)."""
    prepare(count)
    sim = ROOT / "sim"
    sim.mkdir(exist_ok=True)
    namespace: dict[str, object] = {}
    exec(MODEL, namespace)  # the callable the other parts run, to export what it computes
    run = namespace["run"]
    for index in range(count):
        target = sim / f"rec{index:03d}.parquet"
        if not target.exists():
            run(_recording(index)).to_parquet(target, index=False)  # type: ignore[operator]
    for extra in sorted(sim.glob("rec*.parquet"))[count:]:
        extra.unlink()
    spec = ROOT / "campaign-exported.hevval.yaml"
    spec.write_text(
        "reference: {path: data/rec*.parquet}\n"
        "model: {path: 'sim/{id}.parquet'}\n"
        "campaign: {min_pass_rate: 0.5}\n"
        "alignment: {max_lag_s: 2}\nthresholds: {mae: 0.9}\nmin_phi: 0.8\n" + _sets()
    )
    return spec


def _pytest_run(spec: Path, extra: list[str]) -> float:
    """Wall seconds of one whole ``pytest --hevval`` process over ``spec``, as a user runs it."""
    command = [sys.executable, "-m", "pytest", "--hevval", spec.name, "-q", "-p"]
    command += ["no:cacheprovider", "--hevval-no-history", *extra]
    seconds, _, done = timed_run(command, ROOT)
    if done.returncode not in (0, 1) or "campaign" not in done.stdout:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stdout[-3000:]}")
    return seconds


def spread(counts: list[int], repeat: int) -> None:
    """Serial against ``-n 2`` against a two-worker local Dask cluster, for each campaign size,
    the three alternating within each repetition."""
    ways = {
        "serial": [],
        "-n 2": ["-p", "xdist", "-n", "2"],
        "dask": ["--hevval-dask=local"],
    }
    for count in counts:
        spec = prepare_exported(count)
        _pytest_run(spec, [])  # the file cache and the kernel's cache warm for every way
        times: dict[str, list[float]] = {way: [] for way in ways}
        for _ in range(repeat):
            for way, extra in ways.items():
                times[way].append(_pytest_run(spec, extra))
        line = f"{count} recordings at {RATE_HZ:g} Hz ({count * (CHANNELS + 1) + 1} items):"
        for way, found in times.items():
            median = statistics.median(found)
            ratios = [t / s for t, s in zip(found, times["serial"], strict=True)]
            line += (
                f" {way} {median:.2f} s ({min(found):.2f}–{max(found):.2f}; "
                f"÷ serial, per repetition: median {statistics.median(ratios):.2f})"
            )
        print(line, f"load average {os.getloadavg()[0]:.2f}", flush=True)


def score(specs: list[Path], *, campaign: bool, intervals: bool = True) -> tuple[float, float]:
    """(wall, CPU) time of loading and scoring ``specs`` (and the verdict, for a campaign)."""
    from pytest_hevval.results.campaign import campaign_verdicts
    from pytest_hevval.scoring.engine import Evaluation
    from pytest_hevval.scoring.run import RunOptions, run_specs
    from pytest_hevval.spec.load import load_specs

    started, cpu = time.perf_counter(), time.process_time()
    loaded = [spec for path in specs for spec in load_specs(path)]
    outcomes = run_specs(loaded, RunOptions(rootdir=ROOT, intervals=intervals))
    results = [o.result for o in outcomes if isinstance(o, Evaluation)]
    if len(results) != len(loaded):
        raise SystemExit(f"only {len(results)} of {len(loaded)} recordings scored")
    if campaign:
        (verdict,) = campaign_verdicts(results)
        assert len(verdict.recordings) == len(loaded)
    return time.perf_counter() - started, time.process_time() - cpu


def interval_cost(campaign: Path, repeat: int) -> None:
    """The campaign scored with and without intervals, alternating within each repetition."""
    score([campaign], campaign=True)  # warm the file cache and imports
    rows = []
    for repetition in range(1, repeat + 1):
        order = (False, True) if repetition % 2 else (True, False)
        timed = {flag: score([campaign], campaign=True, intervals=flag) for flag in order}
        rows.append((timed[False], timed[True]))
        print(
            f"  repetition {repetition}: wall without {timed[False][0]:.2f} s, with "
            f"{timed[True][0]:.2f} s ({timed[True][0] / timed[False][0]:.3f}); CPU without "
            f"{timed[False][1]:.2f} s, with {timed[True][1]:.2f} s "
            f"({timed[True][1] / timed[False][1]:.3f})"
        )
    for index, what in enumerate(("wall", "CPU")):
        without = min(r[0][index] for r in rows)
        with_ = min(r[1][index] for r in rows)
        median = statistics.median(r[1][index] / r[0][index] for r in rows)
        print(
            f"intervals, {what}: fastest without {without:.2f} s, with {with_:.2f} s, ratio "
            f"{with_ / without:.3f}; median ratio per repetition {median:.3f}"
        )


def u_distribution_timing(calls: int = 300) -> None:
    """Milliseconds per signal: u sample by sample against the engine's shortcut."""
    from pytest_hevval.core.upooling import u_distribution, u_distribution_of, u_values

    reference = _recording(0)["c00"].to_numpy()
    model = np.roll(reference, 3) * 1.01 + np.random.default_rng(1).normal(0, 0.2, reference.size)
    for label, run in (
        ("sample by sample", lambda: u_distribution(u_values(reference, model))),
        ("u_distribution_of", lambda: u_distribution_of(reference, model)),
    ):
        times = []
        for _ in range(calls):
            started = time.perf_counter()
            run()
            times.append(time.perf_counter() - started)
        print(
            f"u distribution of {reference.size} samples, {label}: "
            f"median {statistics.median(times) * 1e3:.2f} ms, fastest {min(times) * 1e3:.2f} ms"
        )


def main() -> None:
    # One benchmark process, one data set: --rate picks it for every part.
    global ROOT, RATE_HZ
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--part",
        choices=("all", "campaign", "intervals", "spread"),
        default="all",
        help="campaign: campaign against single specs; intervals: the campaign with and "
        "without the bootstrap intervals; spread: a campaign over exported model files as "
        "whole pytest runs, serial against -n 2 against Dask (sizes from --counts)",
    )
    parser.add_argument(
        "--counts",
        default="50,100,200",
        help="spread: comma-separated campaign sizes (recordings)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=RATE_HZ,
        help="spread: the recordings' sample rate in Hz (longer scoring per item); data for a "
        "rate other than 10 Hz goes to its own folder",
    )
    args = parser.parse_args()
    if args.rate != RATE_HZ:
        ROOT = ROOT.with_name(f"campaign-{args.rate:g}hz")
        RATE_HZ = args.rate
    if args.part == "spread":
        spread([int(c) for c in args.counts.split(",")], args.repeat)
        return
    singles, campaign = prepare(args.recordings)
    sys.path.insert(0, str(ROOT))
    from pytest_hevval.core.kernel import KERNEL_ENV
    from pytest_hevval.data.kernel_cache import describe

    print(
        f"{args.recordings} recordings of {SECONDS / 60:g} min at {RATE_HZ:g} Hz, "
        f"{CHANNELS} signals; load average {os.getloadavg()[0]:.2f}; "
        f"{KERNEL_ENV}={os.environ.get(KERNEL_ENV, '(unset)')}; {describe()}"
    )
    if args.part in ("all", "intervals"):
        interval_cost(campaign, args.repeat)
    if args.part == "intervals":
        return
    rows: list[tuple[tuple[float, float], tuple[float, float]]] = []
    for repetition in range(1, args.repeat + 1):
        single = score(singles, campaign=False)
        whole = score([campaign], campaign=True)
        rows.append((single, whole))
        print(
            f"  repetition {repetition}: wall single {single[0]:.2f} s, campaign "
            f"{whole[0]:.2f} s ({whole[0] / single[0]:.3f}); CPU single {single[1]:.2f} s, "
            f"campaign {whole[1]:.2f} s ({whole[1] / single[1]:.3f})"
        )
    for index, what in enumerate(("wall", "CPU")):
        fastest_single = min(s[index] for s, _ in rows)
        fastest_campaign = min(c[index] for _, c in rows)
        median = statistics.median(c[index] / s[index] for s, c in rows)
        print(
            f"{what}: fastest single {fastest_single:.2f} s, campaign {fastest_campaign:.2f} s, "
            f"ratio {fastest_campaign / fastest_single:.3f}; median ratio per repetition "
            f"{median:.3f}"
        )
    u_distribution_timing()


if __name__ == "__main__":
    main()
