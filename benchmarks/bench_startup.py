"""What installing pytest-hevval costs a pytest run that has no specs.

pytest loads every installed ``pytest11`` plugin in every run of the environment, so the
plugin must cost next to nothing until ``--hevval`` is given. This runs
``pytest --collect-only`` on a small project with no specs, with the plugin (as installed) and
with it disabled (``-p no:hevval``), alternating the two so that machine noise hits both alike,
and reports the medians and their difference. Goal: at most 30 ms added.

    python benchmarks/bench_startup.py [--repeat 21] [--tests 50]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _project(folder: Path, tests: int) -> None:
    for index in range(tests):
        (folder / f"test_{index:03d}.py").write_text(
            f"def test_{index}():\n    assert {index} + 1 == {index + 1}\n"
        )


def _collect(folder: Path, extra: list[str]) -> float:
    command = [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"]
    start = time.perf_counter()
    subprocess.run(command + extra, cwd=folder, check=True, capture_output=True)
    return time.perf_counter() - start


def _import_cost() -> float:
    """Seconds to import the plugin module alone, in a fresh interpreter."""
    code = (
        "import time; t = time.perf_counter(); import pytest_hevval.plugin; "
        "print(time.perf_counter() - t)"
    )
    # pytest is imported first so that only the plugin's own cost is measured.
    done = subprocess.run(
        [sys.executable, "-c", "import pytest; " + code],
        check=True,
        capture_output=True,
        text=True,
    )
    return float(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=21, help="runs of each variant")
    parser.add_argument("--tests", type=int, default=50, help="test files in the project")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hevval-startup-") as name:
        folder = Path(name)
        _project(folder, args.tests)
        _collect(folder, [])  # warm the file cache
        with_plugin: list[float] = []
        without: list[float] = []
        for _ in range(args.repeat):
            with_plugin.append(_collect(folder, []))
            without.append(_collect(folder, ["-p", "no:hevval"]))
    imports = sorted(_import_cost() for _ in range(5))
    added = statistics.median(with_plugin) - statistics.median(without)
    print(f"pytest --collect-only, {args.tests} test files, {args.repeat} runs each, alternating")
    print(f"  with pytest-hevval:    median {statistics.median(with_plugin) * 1e3:7.1f} ms")
    print(f"  with -p no:hevval:     median {statistics.median(without) * 1e3:7.1f} ms")
    print(f"  added by the plugin:          {added * 1e3:7.1f} ms (goal ≤ 30 ms)")
    print(f"import pytest_hevval.plugin after pytest: median {imports[2] * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
