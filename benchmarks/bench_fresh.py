"""A fresh environment's first run against the same command run a second time.

The README's main command (``pytest --hevval`` in ``example_project/``) is run on a copy of the
example project, twice in a row, each round starting from an empty numba cache
(``NUMBA_CACHE_DIR``) and an empty history folder, as in a new clone: the first run finds no
compiled kernel, the second finds what the first left (the background compile may still be
running when it starts, as when a user runs again at once); ``--third`` adds a run once the
compile has finished, the warm speed the first run is meant to match. ``--venv`` also builds a new
virtual environment with the README's install line (``pip install -e ".[all]"``) and runs the
rounds in it. Goal: the first run within 15 % of the second.

    python benchmarks/bench_fresh.py [--rounds 3] [--venv] [--third]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _env import timed_run, user_environment

ROOT = Path(__file__).resolve().parents[1]


def _run(python: str, project: Path, cache: Path, history: Path) -> tuple[float, float]:
    """The run's wall and CPU seconds (its own process: the background compile is detached)."""
    env = user_environment(NUMBA_CACHE_DIR=str(cache))
    env.pop("HEVVAL_KERNEL", None)
    command = [python, "-m", "pytest", "--hevval", "-q", "-p", "no:cacheprovider"]
    command += [f"--hevval-history-dir={history}"]
    seconds, cpu, done = timed_run(command, project, env)
    if done.returncode not in (0, 1):
        raise SystemExit(f"the example failed to run ({done.returncode}):\n{done.stdout[-2000:]}")
    return seconds, cpu


def _wait_for_compile(cache: Path, limit_s: float = 120.0) -> None:
    """Let a background compile of the previous round end before the next round starts."""
    deadline = time.monotonic() + limit_s
    while any(cache.rglob(".hevval-compiling")) and time.monotonic() < deadline:
        time.sleep(0.5)


def _venv(folder: Path) -> str:
    subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True)
    python = str(folder / "bin" / "python")
    started = time.perf_counter()
    subprocess.run(
        [python, "-m", "pip", "install", "-q", "-e", f"{ROOT}[all]"], check=True, cwd=ROOT
    )
    print(f"install: {time.perf_counter() - started:.1f} s (pip install -e '.[all]')")
    return python


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds of first + second run")
    parser.add_argument("--venv", action="store_true", help="build a new venv first")
    parser.add_argument("--third", action="store_true", help="a third run once compiled")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hevval-fresh-") as name:
        work = Path(name)
        python = _venv(work / "venv") if args.venv else sys.executable
        project = work / "example_project"
        shutil.copytree(
            ROOT / "example_project", project, ignore=shutil.ignore_patterns(".hevval*")
        )
        first: list[float] = []
        second: list[float] = []
        third: list[float] = []
        cpu: dict[str, list[float]] = {"first": [], "second": [], "third": []}
        for index in range(args.rounds):
            cache = work / f"numba-{index}"
            history = work / f"history-{index}"
            for name, times in (("first", first), ("second", second)):
                wall, used = _run(python, project, cache, history / name)
                times.append(wall)
                cpu[name].append(used)
            if args.third:
                _wait_for_compile(cache)
                wall, used = _run(python, project, cache, history / "third")
                third.append(wall)
                cpu["third"].append(used)
            line = f"round {index + 1}: first {first[-1]:.2f} s, second {second[-1]:.2f} s"
            if third:
                line += f", third (compiled) {third[-1]:.2f} s"
            line += " (CPU " + ", ".join(f"{times[-1]:.2f}" for times in cpu.values() if times)
            line += " s)"
            line += f" (first/second {first[-1] / second[-1]:.2f}×"
            if third:
                line += f", first/third {first[-1] / third[-1]:.2f}×"
            print(line + ")", flush=True)
            _wait_for_compile(cache)
        ratios = [a / b for a, b in zip(first, second, strict=True)]
        print(
            f"median: first {statistics.median(first):.2f} s, second "
            f"{statistics.median(second):.2f} s; first/second per round: median "
            f"{statistics.median(ratios):.2f}× (min {min(ratios):.2f}, max {max(ratios):.2f})"
        )
        if third:
            warm = [a / b for a, b in zip(first, third, strict=True)]
            print(
                f"median third (compile finished): {statistics.median(third):.2f} s; "
                f"first/third per round: median {statistics.median(warm):.2f}× "
                f"(min {min(warm):.2f}, max {max(warm):.2f})"
            )


if __name__ == "__main__":
    main()
