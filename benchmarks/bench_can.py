"""Reading a CAN log: 1 h of 2,000 frames/s (7.2 M frames) decoded to 300 signals.

    python benchmarks/bench_can.py                 # builds the log once, then times reading
    python benchmarks/bench_can.py --minutes 5     # a shorter log for a quick look
    python benchmarks/bench_can.py --minutes 2 --text-logs --repeat 1   # BLF, ASC, candump

The log is a Vector BLF file written by python-can: 20 messages at 100 Hz, each with 15
signals (half Intel, half Motorola; signed and unsigned; lengths of 2 to 8 bits; scales and
offsets), described by a DBC written with cantools. Payloads are generated vectorised; a sample
of them is checked against cantools' encoder, and the decoded values of a sample of frames
against cantools' ``decode_message``. The target is reading faster than the log's duration by
100×, i.e. ≤ 36 s for the hour. Each timing runs ``read_record`` in a fresh process; the frame
read (python-can) and the decode are also reported on their own.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

MESSAGES = 20
SIGNALS_PER_MESSAGE = 15
RATE_HZ = 100.0
# Bit lengths of the 15 signals of a message: 64 bits in all.
LENGTHS = (8, 4, 4, 6, 2, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4)
START_EPOCH_S = 1_767_225_600.0  # 2026-01-01T00:00:00Z
DEFAULT_CACHE = Path(tempfile.gettempdir()) / "hevval-bench" / "can"


def _vm_hwm_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0


def build_database(path: Path) -> Any:
    """20 messages × 15 signals; odd messages Motorola, every third signal signed."""
    import cantools
    from cantools.database.can import Database, Message, Signal

    messages = []
    for m in range(MESSAGES):
        big_endian = m % 2 == 1
        signals = []
        bit = 0  # Intel: LSB position; Motorola: MSB-first position in the payload
        for s, length in enumerate(LENGTHS):
            # Motorola signals are placed by their MSB in DBC numbering.
            start = 8 * (bit // 8) + 7 - bit % 8 if big_endian else bit
            signals.append(
                Signal(
                    name=f"m{m:02d}_s{s:02d}",
                    start=start,
                    length=length,
                    byte_order="big_endian" if big_endian else "little_endian",
                    is_signed=s % 3 == 1,
                    conversion=cantools.database.conversion.BaseConversion.factory(
                        scale=0.5 if s % 2 else 1, offset=-10 if s % 4 == 2 else 0
                    ),
                    unit="u",
                )
            )
            bit += length
        messages.append(Message(frame_id=0x100 + m, name=f"msg{m:02d}", length=8, signals=signals))
    database = Database(messages=messages)
    path.write_text(database.as_dbc_string())
    return cantools.database.load_file(str(path))


def _payloads(rng: np.random.Generator, rows: int, big_endian: bool) -> np.ndarray:
    """Random raw values of every signal packed into 8-byte payloads, vectorised."""
    packed = np.zeros(rows, dtype=np.uint64)
    bit = 0
    for length in LENGTHS:
        raw = rng.integers(0, 1 << length, rows, dtype=np.uint64)
        shift = 64 - bit - length if big_endian else bit
        packed |= raw << np.uint64(shift)
        bit += length
    return packed.astype(">u8" if big_endian else "<u8").view(np.uint8).reshape(rows, 8)


def build_log(path: Path, database: Any, minutes: float) -> float:
    """Write the BLF log; return the seconds it took."""
    import can

    started = time.perf_counter()
    rng = np.random.default_rng(7)
    steps = round(minutes * 60 * RATE_HZ)
    messages = database.messages
    chunk = 6000  # steps per chunk: 1 minute
    tmp = path.with_suffix(".tmp")
    with can.BLFWriter(str(tmp)) as writer:
        write = writer.on_message_received
        for first in range(0, steps, chunk):
            count = min(chunk, steps - first)
            step_time = START_EPOCH_S + (first + np.arange(count)) / RATE_HZ
            payloads = [_payloads(rng, count, m % 2 == 1) for m in range(MESSAGES)]
            if first == 0:
                _check_encoder(messages, payloads)
            for i in range(count):
                base = float(step_time[i])
                for m, message in enumerate(messages):
                    write(
                        can.Message(
                            timestamp=base + m * 2.5e-4,
                            arbitration_id=message.frame_id,
                            is_extended_id=False,
                            data=payloads[m][i].tobytes(),
                        )
                    )
    tmp.replace(path)
    return time.perf_counter() - started


def _check_encoder(messages: Any, payloads: list[np.ndarray]) -> None:
    """The vectorised payloads are what cantools' encoder makes of their decoded values."""
    for message, block in zip(messages, payloads, strict=True):
        for row in block[:50]:
            values = message.decode(row.tobytes(), decode_choices=False)
            if message.encode(values) != row.tobytes():
                raise SystemExit(f"payload packing differs from cantools for {message.name}")


def _check_decode(record: Any, path: Path, database: Any) -> dict[str, float]:
    """Compare the decoded channels with cantools on the first 20,000 frames of the log.

    Also times ``decode_message`` alone on those frames: the per-frame decode a reader would
    otherwise do.
    """
    import can

    frames = []
    with can.BLFReader(str(path)) as reader:
        for frame in reader:
            frames.append((frame.arbitration_id, bytes(frame.data)))
            if len(frames) == 20_000:
                break
    start = time.perf_counter()
    decoded = [database.decode_message(i, d, decode_choices=False) for i, d in frames]
    per_frame = (time.perf_counter() - start) / len(frames)
    seen: dict[int, int] = {}
    checked = 0
    for (frame_id, _), values in zip(frames, decoded, strict=True):
        index = seen.get(frame_id, 0)
        seen[frame_id] = index + 1
        for name, value in values.items():
            if record.channels[name].values[index] != float(value):
                raise SystemExit(f"{name}: frame {index} decodes differently from cantools")
            checked += 1
    return {"values_checked_against_cantools": checked, "cantools_decode_s_per_frame": per_frame}


def child(path: str, database_path: str, stages: bool) -> None:
    from pytest_hevval.data.readers import can as can_reader
    from pytest_hevval.data.readers import read_record
    from pytest_hevval.data.record import SourceOptions

    options = SourceOptions(extra={"dbc": database_path})
    baseline = _vm_hwm_kib()
    figures: dict[str, Any] = {}
    if stages:
        start = time.perf_counter()
        frames = can_reader._read_frames(path)
        figures["read_frames_s"] = time.perf_counter() - start
        figures["frames"] = int(frames.time.size)
        del frames
    start = time.perf_counter()
    record = read_record(path, None, options)
    figures["seconds"] = time.perf_counter() - start
    figures["peak_growth_bytes"] = (_vm_hwm_kib() - baseline) * 1024
    figures["channels"] = len(record.channels)
    figures["values"] = sum(c.values.size for c in record.channels.values())
    figures["can"] = record.meta["can"]
    figures["load_average_1min"] = os.getloadavg()[0]
    if not stages:
        import cantools

        database = cantools.database.load_file(database_path)
        figures.update(_check_decode(record, Path(path), database))
    print(json.dumps(figures))


def compare_text_logs(log: Path, database_path: Path) -> None:
    """Write the log again as ASC and candump with python-can; time one read of each."""
    import can

    from pytest_hevval.data.readers import read_record
    from pytest_hevval.data.record import SourceOptions

    copies = {".asc": can.ASCWriter, ".log": can.CanutilsLogWriter}
    for suffix, writer_class in copies.items():
        target = log.with_suffix(suffix)
        if not target.exists():
            with can.BLFReader(str(log)) as reader, writer_class(str(target)) as writer:
                for frame in reader:
                    writer.on_message_received(frame)
    options = SourceOptions(extra={"dbc": str(database_path)})
    for suffix in (".blf", ".asc", ".log"):
        start = time.perf_counter()
        record = read_record(str(log.with_suffix(suffix)), None, options)
        seconds = time.perf_counter() - start
        frames = record.meta["can"]["frames"]
        print(f"{suffix}: {frames} frames, {len(record.channels)} signals in {seconds:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0, help="log duration (60)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE)
    parser.add_argument(
        "--text-logs",
        action="store_true",
        help="also write the log as ASC and candump and time one read of each, side by side",
    )
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--stages", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], args.child[1], args.stages)
        return

    args.cache_dir.mkdir(parents=True, exist_ok=True)
    database_path = args.cache_dir / "bench.dbc"
    database = build_database(database_path)
    log = args.cache_dir / f"bench-{args.minutes:g}min.blf"
    if not log.exists():
        print(f"building {log} ...", flush=True)
        seconds = build_log(log, database, args.minutes)
        print(f"built in {seconds:.1f} s ({log.stat().st_size / 1e6:.0f} MB)", flush=True)
    if args.text_logs:
        compare_text_logs(log, database_path)
    duration = args.minutes * 60
    budget = duration / 100
    runs = []
    for attempt in range(args.repeat):
        command = [sys.executable, __file__, "--child", str(log), str(database_path)]
        if attempt:
            command.append("--stages")
        out = subprocess.run(command, capture_output=True, text=True, check=True, env=os.environ)
        figures = json.loads(out.stdout.strip().splitlines()[-1])
        runs.append(figures)
        print(json.dumps(figures), flush=True)
    best = min(r["seconds"] for r in runs)
    print(
        f"{runs[0]['can']['frames']} frames, {runs[0]['channels']} signals: read + decode "
        f"best {best:.1f} s of {args.repeat} (budget {budget:.1f} s = duration / 100: "
        f"{'met' if best <= budget else 'MISSED'})"
    )


if __name__ == "__main__":
    main()
