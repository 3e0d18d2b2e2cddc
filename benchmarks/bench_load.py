"""Loading a spec's columns: 600 channels × 1 h at 100 Hz from Parquet and MF4, CSV beside it.

    python benchmarks/bench_scale.py --full --only e2e   # once: generates benchmarks/.data/
    python benchmarks/bench_load.py                      # targets: ≤ 5 s, peak ≤ 1.5× the columns

Each measurement runs `read_record` in a fresh process and reports wall time and the growth of
peak RSS over the process's baseline, against the float64 size of the columns loaded. CSV is
measured on the first 60 channels (a 600-channel hour as text would be about 4 GB) and its rate
reported per value, for comparison.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

DATA = Path(__file__).resolve().parent / ".data" / "e2e-600x360000"


def _vm_hwm_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0


def child(path: str, columns: int, fmt: str | None) -> None:
    """Read ``columns`` channels of ``path`` once; print one JSON line of figures."""
    from pytest_hevval.data.readers import read_record
    from pytest_hevval.data.record import SourceOptions

    options = SourceOptions(time="time", format=fmt)
    names = read_record(path, [], options).available
    wanted = [n for n in names if n != "time"][:columns]
    baseline = _vm_hwm_kib()
    start = time.perf_counter()
    record = read_record(path, wanted, options)
    elapsed = time.perf_counter() - start
    peak = _vm_hwm_kib()
    values = sum(c.values.shape[0] for c in record.channels.values())
    print(
        json.dumps(
            {
                "path": Path(path).name,
                "channels": len(record.channels),
                "values": values,
                "seconds": elapsed,
                "column_bytes": values * 8,
                "peak_growth_bytes": (peak - baseline) * 1024,
            }
        )
    )


def _run_child(path: Path, columns: int, fmt: str | None = None) -> dict[str, float]:
    command = [sys.executable, __file__, "--child", str(path), "--columns", str(columns)]
    if fmt:
        command += ["--format", fmt]
    out = subprocess.run(command, capture_output=True, text=True, check=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def _write_csv(source: Path, target: Path, columns: int) -> None:
    import pyarrow.parquet as pq

    table = pq.read_table(source, columns=None)
    names = ["time", *[n for n in table.column_names if n != "time"][:columns]]
    table.select(names).to_pandas().to_csv(target, index=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--columns", type=int, default=600, help=argparse.SUPPRESS)
    parser.add_argument("--format", help=argparse.SUPPRESS)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    if args.child:
        child(args.child, args.columns, args.format)
        return
    if not (DATA / ".complete").exists():
        sys.exit("no data: run `python benchmarks/bench_scale.py --full --only e2e` first")
    csv = DATA / "ref-60.csv"
    if not csv.exists():
        _write_csv(DATA / "ref.parquet", csv, 60)
    rows = [
        ("Parquet, 600 channels", DATA / "ref.parquet", 600),
        ("MF4, 600 channels", DATA / "ref.mf4", 600),
        # A spec that uses a few channels of a wide log: memory must follow what is read.
        ("Parquet, 10 channels", DATA / "ref.parquet", 10),
        ("MF4, 10 channels", DATA / "ref.mf4", 10),
        ("CSV, 60 channels", csv, 60),
    ]
    print(f"{'source':<24}{'best s':>8}{'median s':>10}{'ns/value':>10}{'peak/cols':>11}")
    for label, path, columns in rows:
        runs = [_run_child(path, columns) for _ in range(args.repeat)]
        times = sorted(r["seconds"] for r in runs)
        best = runs[[r["seconds"] for r in runs].index(times[0])]
        ratio = max(r["peak_growth_bytes"] / r["column_bytes"] for r in runs)
        per_value = 1e9 * times[0] / best["values"]
        print(
            f"{label:<24}{times[0]:>8.2f}{times[len(times) // 2]:>10.2f}"
            f"{per_value:>10.2f}{ratio:>10.2f}×"
        )


if __name__ == "__main__":
    main()
