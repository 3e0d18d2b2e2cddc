"""Behaviour under degenerate signals, faults, parallelism and hostile input.

docs/reliability.md holds the table of degenerate signals checked here, the fault figures and
the trust model. ``HEVVAL_KILL_ROUNDS=N`` kills the history writer N times instead of 2, and
``HEVVAL_KILL_FIGURES=file`` appends what the kills left behind to that file as JSON lines.
"""

from __future__ import annotations

import errno
import json
import os
import random
import re
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pytest
import yaml

import pytest_hevval
from pytest_hevval.core.characteristics import (
    CHARACTERISTICS,
    SignalCharacteristics,
    signal_characteristics,
)
from pytest_hevval.errors import DataError, DegenerateSignalError, HevvalError, SpecError
from pytest_hevval.history import HistoryError, HistoryStore, make_record
from pytest_hevval.scoring import signal_pass
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import load_spec, parse_spec_text
from pytest_hevval.spec.yaml_lines import load_yaml_with_lines

Array = npt.NDArray[np.float64]

DT = 0.1
N = 400
T = np.arange(N) * DT
BASE = np.sin(T) + 0.3 * np.cos(3.1 * T)
NEAR = BASE + 0.05 * np.sin(7.0 * T)


def _in_unit_interval(result: SignalCharacteristics) -> None:
    assert all(0.0 <= value <= 1.0 for value in result.lambdas), result.lambdas
    assert np.isfinite(result.lag_s)


# --------------------------------------------------------------------------------------------
# Degenerate signals through signal_characteristics (the table in docs/reliability.md)


@pytest.mark.parametrize(
    ("case", "reference", "simulated", "message"),
    [
        ("constant", np.full(N, 5.0), np.full(N, 5.0), "the reference is constant"),
        ("constant reference", np.full(N, 5.0), 5.0 + BASE, "the reference is constant"),
        ("all zero", np.zeros(N), np.zeros(N), "the reference is constant"),
        ("2 samples", BASE[:2], NEAR[:2], "at least 3 samples are needed (got 2)"),
        ("0 samples", BASE[:0], NEAR[:0], "at least 3 samples are needed (got 0)"),
        ("NaN", BASE, np.where(T[7] == T, np.nan, NEAR), "simulated signal contains NaN"),
        ("inf", np.where(T[3] == T, np.inf, BASE), NEAR, "reference signal contains NaN or inf"),
        ("float32 overflow", BASE.astype(np.float32) * np.float32(np.inf), NEAR, "NaN or inf"),
        ("lengths differ", BASE, NEAR[:-1], "differ in length (400 vs 399 samples)"),
    ],
    ids=lambda value: value if isinstance(value, str) and len(value) < 24 else None,
)
def test_degenerate_pairs_raise_a_clear_error(
    case: str, reference: Array, simulated: Array, message: str
) -> None:
    with np.errstate(invalid="ignore"), pytest.raises(DegenerateSignalError) as caught:
        signal_characteristics(reference, simulated, dt=DT)
    assert message in str(caught.value)
    if "constant" in message:
        assert "declare a normalising range (reference_range)" in str(caught.value)


@pytest.mark.parametrize("dt", [0.0, -0.1, float("nan"), float("inf")])
def test_bad_sample_spacing_is_a_clear_error(dt: float) -> None:
    with pytest.raises(DegenerateSignalError, match="dt"):
        signal_characteristics(BASE, NEAR, dt=dt)


@pytest.mark.parametrize(
    ("case", "reference", "simulated"),
    [
        ("constant", np.full(N, 5.0), np.full(N, 5.0)),
        ("all zero", np.zeros(N), np.zeros(N)),
    ],
)
def test_constant_pairs_with_a_declared_range_match_perfectly(
    case: str, reference: Array, simulated: Array
) -> None:
    result = signal_characteristics(reference, simulated, dt=DT, reference_range=1.0)
    assert result.lambdas == (1.0,) * 6
    assert result.mae == result.rms == 0.0


def test_constant_reference_with_a_declared_range_scores_the_error() -> None:
    result = signal_characteristics(np.zeros(N), 0.1 * BASE, dt=DT, reference_range=1.0)
    _in_unit_interval(result)
    assert result.lambdas[2] == pytest.approx(1.0 - float(np.mean(np.abs(0.1 * BASE))))


def test_all_zero_model_output_scores_zero_correlation() -> None:
    result = signal_characteristics(BASE, np.zeros(N), dt=DT)
    _in_unit_interval(result)
    assert result.lambdas[0] == 0.0


def test_identical_constant_signals_have_no_lag() -> None:
    result = signal_characteristics(np.full(N, 5.0), np.full(N, 5.0), dt=DT, reference_range=1.0)
    assert result.lag_s == 0.0


def test_three_samples_are_enough() -> None:
    result = signal_characteristics(BASE[:3], NEAR[:3], dt=DT)
    _in_unit_interval(result)
    assert result.n_samples == 3


@pytest.mark.parametrize("scale", [2.0**900, 2.0**-900, 1e300, 1e-300, 1e308 / 2])
def test_huge_and_tiny_magnitudes_score_like_unit_ones(scale: float) -> None:
    # λ are ratios, so scaling both signals by one factor must not change them.
    unit = signal_characteristics(BASE, NEAR, dt=DT)
    scaled = signal_characteristics(BASE * scale, NEAR * scale, dt=DT)
    assert scaled.lambdas == pytest.approx(unit.lambdas, rel=1e-12, abs=1e-15)
    assert scaled.lag_s == unit.lag_s
    assert scaled.mae == pytest.approx(unit.mae * scale, rel=1e-12)


def test_subnormal_magnitudes_score_close_to_unit_ones() -> None:
    # MAE, RMS and σ are returned at the signal's own scale, where a subnormal number carries
    # only a few significant bits; λ3–λ6 divide two of them, hence the looser tolerance.
    unit = signal_characteristics(np.sign(BASE), np.sign(NEAR), dt=DT)
    tiny = signal_characteristics(5e-320 * np.sign(BASE), 5e-320 * np.sign(NEAR), dt=DT)
    assert tiny.lambdas == pytest.approx(unit.lambdas, rel=1e-4)
    assert tiny.lambdas[:2] == unit.lambdas[:2]
    assert tiny.lag_s == unit.lag_s


def test_float32_input_matches_float64_of_the_same_values() -> None:
    reference = BASE.astype(np.float32)
    simulated = NEAR.astype(np.float32)
    single = signal_characteristics(reference, simulated, dt=DT)
    double = signal_characteristics(
        reference.astype(np.float64), simulated.astype(np.float64), dt=DT
    )
    assert single == double


# More samples than the exact lag search handles, so the coarse-to-fine path runs.
LONG = (1 << 18) + 1


def test_long_signals_score() -> None:
    rng = np.random.default_rng(7)
    reference = np.cumsum(rng.normal(size=LONG))
    identical = signal_characteristics(reference, reference.copy(), dt=0.01)
    # Errors are exactly zero; λ1 is a ratio of two long sums and may round to 1 − 1 ulp.
    assert identical.lambdas[1:] == (1.0,) * 5
    assert identical.lambdas[0] == pytest.approx(1.0, abs=1e-15)
    assert identical.lag_s == 0.0
    shifted = signal_characteristics(reference[25:], reference[:-25], dt=0.01)
    assert shifted.lag_s == pytest.approx(-0.25)


def test_long_signals_near_the_float_limit() -> None:
    t = np.arange(LONG) * 0.1
    unit = np.sin(t) + 0.3 * np.cos(3.1 * t)
    result = signal_characteristics(5e307 * unit, 5e307 * 0.99 * unit, dt=0.1)
    assert result.lag_s == 0.0
    assert result.peak_correlation == pytest.approx(1.0)
    at_unit_scale = signal_characteristics(unit, 0.99 * unit, dt=0.1)
    assert result.lambdas == pytest.approx(at_unit_scale.lambdas, rel=1e-12)


# --------------------------------------------------------------------------------------------
# Degenerate signals through the whole engine


def _write_pair(
    folder: Path, reference: npt.NDArray[Any], simulated: npt.NDArray[Any], dt: float = DT
) -> None:
    t = np.arange(len(reference)) * dt
    pd.DataFrame({"time": t, "v": reference}).to_parquet(folder / "ref.parquet")
    pd.DataFrame({"time": t, "v": simulated}).to_parquet(folder / "sim.parquet")


def _spec(folder: Path, sets: str, extra: str = "") -> Any:
    text = f"reference: ref.parquet\nmodel: sim.parquet\n{extra}sets:\n{sets}"
    path = folder / "degenerate.hevval.yaml"
    path.write_text(text)
    return load_spec(path)


ONE = "  - {signal: v}\n"


@pytest.mark.parametrize(
    ("case", "reference", "simulated", "sets", "extra", "error", "message"),
    [
        (
            "constant",
            np.full(N, 5.0),
            np.full(N, 5.0),
            ONE,
            "",
            DegenerateSignalError,
            "degenerate.hevval.yaml:4: sets[0]: the reference is constant",
        ),
        (
            "all zero",
            np.zeros(N),
            np.zeros(N),
            ONE,
            "",
            DegenerateSignalError,
            "degenerate.hevval.yaml:4: sets[0]: the reference is constant",
        ),
        (
            "2 samples",
            BASE[:2],
            NEAR[:2],
            ONE,
            "",
            DataError,
            "ref.parquet: the overlap [0, 0.1] s holds fewer than 3 samples",
        ),
        (
            "1 sample",
            BASE[:1],
            NEAR[:1],
            ONE,
            "",
            DataError,
            "ref.parquet: cannot infer the sample rate",
        ),
        (
            "NaN",
            BASE,
            np.where(T[5] == T, np.nan, NEAR),
            ONE,
            "",
            DataError,
            "sim.parquet: column 'v': 1 NaN or inf values (first at t = 0.5 s)",
        ),
        (
            "all NaN, omitted",
            BASE,
            np.full(N, np.nan),
            ONE,
            "alignment: {nan: omit}\n",
            DataError,
            "sim.parquet: column 'v': every value is NaN or inf",
        ),
        (
            "inf",
            np.where(T[5] == T, np.inf, BASE),
            NEAR,
            ONE,
            "",
            DataError,
            "ref.parquet: column 'v': 1 NaN or inf values",
        ),
    ],
    ids=lambda value: value if isinstance(value, str) and len(value) < 24 else None,
)
def test_engine_errors_on_degenerate_data(
    tmp_path: Path,
    case: str,
    reference: Array,
    simulated: Array,
    sets: str,
    extra: str,
    error: type[HevvalError],
    message: str,
) -> None:
    _write_pair(tmp_path, reference, simulated)
    spec = _spec(tmp_path, sets, extra)
    with pytest.raises(error) as caught:
        evaluate_spec(spec, workers=1)
    assert message in str(caught.value)
    assert str(tmp_path) in str(caught.value)


def _lambdas(result: Any) -> dict[str, dict[str, float]]:
    return {s.path: dict(s.lambdas) for s in result.signals}


@pytest.mark.parametrize(
    ("case", "reference", "simulated"),
    [
        ("constant", np.full(N, 5.0), np.full(N, 5.0)),
        ("all zero", np.zeros(N), np.zeros(N)),
    ],
)
def test_engine_scores_constant_signals_with_a_declared_range(
    tmp_path: Path, case: str, reference: Array, simulated: Array
) -> None:
    _write_pair(tmp_path, reference, simulated)
    result = evaluate_spec(_spec(tmp_path, "  - {signal: v, reference_range: 1}\n")).result
    assert _lambdas(result) == {"v": dict.fromkeys(CHARACTERISTICS, 1.0)}
    assert result.phi == 1.0


@pytest.mark.parametrize("scale", [1e300, 1e-300])
def test_engine_scores_huge_and_tiny_magnitudes(tmp_path: Path, scale: float) -> None:
    _write_pair(tmp_path, BASE, NEAR)
    unit = evaluate_spec(_spec(tmp_path, ONE)).result
    _write_pair(tmp_path, BASE * scale, NEAR * scale)
    scaled = evaluate_spec(_spec(tmp_path, ONE)).result
    assert scaled.signals[0].lambdas == pytest.approx(unit.signals[0].lambdas, rel=1e-12)
    assert scaled.phi == pytest.approx(unit.phi, rel=1e-12)


def test_engine_scores_three_samples(tmp_path: Path) -> None:
    _write_pair(tmp_path, BASE[:3], NEAR[:3])
    result = evaluate_spec(_spec(tmp_path, ONE)).result
    assert result.alignment.n_samples == 3
    assert 0.0 <= result.phi <= 1.0


def test_engine_float32_files_match_float64_files(tmp_path: Path) -> None:
    reference = BASE.astype(np.float32)
    simulated = NEAR.astype(np.float32)
    _write_pair(tmp_path, reference, simulated)
    single = evaluate_spec(_spec(tmp_path, ONE)).result
    _write_pair(tmp_path, reference.astype(np.float64), simulated.astype(np.float64))
    double = evaluate_spec(_spec(tmp_path, ONE)).result
    assert _lambdas(single) == _lambdas(double)
    assert single.phi == double.phi


def test_engine_single_signal_set(tmp_path: Path) -> None:
    _write_pair(tmp_path, BASE, NEAR)
    result = evaluate_spec(_spec(tmp_path, ONE)).result
    (only,) = result.signals
    assert list(only.lambdas) == list(CHARACTERISTICS)
    assert only.lambdas["emergent"] == 1.0  # a leaf has no children to disagree with
    assert result.phi == pytest.approx(sum(only.lambdas.values()) / 7)


def test_engine_signal_shared_by_two_sets_is_scored_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write_pair(tmp_path, BASE, NEAR)
    calls: list[int] = []
    real = signal_pass.signal_characteristics

    def counting(*args: Any, **kwargs: Any) -> SignalCharacteristics:
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(signal_pass, "signal_characteristics", counting)
    sets = (
        "  - {signal: A, ref: v, sim: v, children: [{signal: v}]}\n"
        "  - {signal: B, ref: v, sim: v, children: [{signal: v}]}\n"
    )
    result = evaluate_spec(_spec(tmp_path, sets)).result
    assert [s.path for s in result.signals] == ["A", "A/v", "B", "B/v"]
    assert len({tuple(s.lambdas[n] for n in CHARACTERISTICS[:6]) for s in result.signals}) == 1
    assert [s.set for s in result.signals] == [1, 1, 2, 2]
    assert len(calls) == 1


def test_engine_long_signal(tmp_path: Path) -> None:
    t = np.arange(LONG) * 0.01
    reference = np.sin(t) + 0.1 * np.sin(13 * t)
    _write_pair(tmp_path, reference, reference + 0.01, dt=0.01)
    result = evaluate_spec(_spec(tmp_path, ONE, "alignment: {max_lag_s: 1}\n"))
    assert result.result.alignment.n_samples == LONG
    assert result.result.signals[0].lag_s == 0.0
    assert result.result.signals[0].lambdas["lag_correlation"] > 0.99


def test_engine_omits_gaps_when_asked(tmp_path: Path) -> None:
    _write_pair(tmp_path, BASE, np.where(T[5] == T, np.nan, NEAR))
    result = evaluate_spec(_spec(tmp_path, ONE, "alignment: {nan: omit}\n")).result
    assert result.alignment.coverage < 1.0
    assert 0.0 <= result.phi <= 1.0


# --------------------------------------------------------------------------------------------
# History under faults

KILL_ROUNDS = int(os.environ.get("HEVVAL_KILL_ROUNDS", "2") or 2)

WRITER = """
import os, sys
from datetime import datetime, timedelta, timezone
from pytest_hevval.history import HistoryStore, make_record

folder, label, mode = sys.argv[1:4]
if mode == "no-links":
    def refuse(src, dst):
        raise PermissionError("hard links not supported")
    os.link = refuse
store = HistoryStore(folder)
start = datetime(2024, 5, 1, tzinfo=timezone.utc)
# Many signals make each record large, so that a kill often lands inside a write.
signals = [{"path": f"s/{k}", "lambdas": [0.5] * 7, "mae": k * 0.1} for k in range(300)]
print("ready", flush=True)
i = 0
while True:
    signals[0]["n_samples"] = i
    record = make_record(
        [{"name": label, "phi": 0.5, "signals": signals}],
        model_version=f"{label}-{i}",
        started_utc=start + timedelta(seconds=i),
    )
    path = store.append(record)
    print(i, path, flush=True)
    i += 1
"""


def _kill_writer(folder: Path, label: str, mode: str, delay: float) -> dict[int, Path]:
    """Run the writer, SIGKILL it after ``delay`` s; return the records it finished."""
    process = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(folder), label, mode],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    assert process.stdout.readline() == "ready\n"
    try:
        process.wait(timeout=delay)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGKILL)
    assert process.wait(timeout=60) == -signal.SIGKILL
    finished: dict[int, Path] = {}
    for line in process.stdout.read().splitlines(keepends=True):
        if line.endswith("\n"):  # a line cut by the kill names no finished record
            index, path = line.split(" ", 1)
            finished[int(index)] = Path(path.strip())
    process.stdout.close()
    return finished


@pytest.mark.parametrize("mode", ["links", "no-links"])
def test_history_survives_sigkill_mid_write(tmp_path: Path, mode: str) -> None:
    rng = random.Random(f"sigkill-{mode}")
    folder = tmp_path / "history"
    finished_total = 0
    for round_index in range(KILL_ROUNDS):
        label = f"r{round_index}"
        finished = _kill_writer(folder, label, mode, rng.uniform(0.02, 0.4))
        finished_total += len(finished)
        for index, path in finished.items():
            record = json.loads(path.read_text(encoding="utf-8"))
            assert record["model_version"] == f"{label}-{index}"
            assert record["specs"][0]["signals"][0]["n_samples"] == index
        store = HistoryStore(folder)
        stored = {r["model_version"] for r in store.records()}
        expected = {f"{label}-{i}" for i in finished}
        assert expected <= stored
        # At most the record in flight was published before its path was printed.
        in_flight = stored - expected - {v for v in stored if not v.startswith(f"{label}-")}
        assert len(in_flight) <= 1
        for problem in store.problems:
            # Without hard links a name is reserved by an empty file first; a kill between
            # reserving and filling leaves it, listed as a problem and never as a record.
            assert mode == "no-links"
            assert problem.message.startswith("empty file")
    store = HistoryStore(folder)
    records = store.records()
    assert all(len(r["specs"][0]["signals"]) == 300 for r in records)
    figures_file = os.environ.get("HEVVAL_KILL_FIGURES")
    if figures_file:
        figures = {
            "mode": mode,
            "kills": KILL_ROUNDS,
            "records_finished": finished_total,
            "records_readable": len(records),
            "empty_placeholders": len(store.problems),
            "temp_files_left": len(list(folder.glob(".tmp-*"))),
        }
        with open(figures_file, "a", encoding="utf-8") as handle:
            handle.write(json.dumps(figures) + "\n")


@pytest.mark.parametrize("achieved", [0.9999999999999999, 0.9299999999999999, 0.93, 1.0])
def test_ratchet_never_sets_a_threshold_above_what_the_run_achieved(achieved: float) -> None:
    from pytest_hevval.history import ratchet_thresholds
    from pytest_hevval.results.spec_result import SpecResult

    signal = {"path": "a", "set": 1, "level": 1, "alpha": 1.0, "lambdas": [achieved] * 7}
    errors = {"lag_s": 0.0, "peak_correlation": 1.0, "mae": 0.0, "rms": 0.0}
    result = SpecResult.from_dict(
        {
            "name": "s",
            "spec": "s.hevval.yaml",
            "phi": 0.5,
            "signals": [{**signal, **errors, "thresholds": {"mae": 0.0}}],
        }
    )
    proposed = ratchet_thresholds(result, {"a": {"mae": 0.0}}, 0.0)["a"]["mae"]
    assert proposed <= achieved
    assert proposed >= achieved - 1e-4


START = datetime(2024, 5, 1, tzinfo=timezone.utc)


def _record(version: str) -> dict[str, Any]:
    spec = {"name": "s", "phi": 0.5, "signals": [{"path": "a", "lambdas": [0.5] * 7}]}
    return make_record([spec], model_version=version, started_utc=START + timedelta(hours=1))


def _no_space(*args: Any, **kwargs: Any) -> Any:
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _full_device(fd: int, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
    # /dev/full accepts opening and fails every write with ENOSPC, as a full disk does.
    os.close(fd)
    return open("/dev/full", mode, buffering=0)


@pytest.mark.parametrize(
    "fault",
    [
        pytest.param({"fsync": _no_space}, id="fsync"),
        pytest.param(
            {"fdopen": _full_device},
            id="write",
            marks=pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full"),
        ),
        pytest.param({"link": _no_space, "open": _no_space}, id="link-and-reserve"),
        pytest.param({"link": _no_space, "replace": _no_space}, id="link-and-replace"),
        pytest.param({"mkdir": _no_space}, id="mkdir"),
    ],
)
def test_full_disk_is_a_clear_error_and_keeps_history(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fault: dict[str, Callable[..., Any]]
) -> None:
    folder = tmp_path / "history"
    if "mkdir" in fault:
        folder = tmp_path / "new" / "history"
    store = HistoryStore(folder)
    if "mkdir" not in fault:
        store.append(_record("before"))
    before = sorted(folder.glob("*.json")) if folder.exists() else []
    real_open = os.open
    for name, replacement in fault.items():
        if name == "open":
            # Only the exclusive reservation of the final name fails; reading stays possible.
            def reserve(path: Any, flags: int, *args: Any, **kwargs: Any) -> int:
                if flags & os.O_EXCL and str(path).endswith(".json"):
                    _no_space()
                return real_open(path, flags, *args, **kwargs)

            monkeypatch.setattr(os, "open", reserve)
        elif name == "mkdir":
            monkeypatch.setattr(Path, "mkdir", replacement)
        else:
            monkeypatch.setattr(os, name, replacement)
    with pytest.raises(HistoryError) as caught:
        store.append(_record("after"))
    monkeypatch.undo()
    message = str(caught.value)
    assert message.startswith(f"{folder}: ")
    assert "No space left on device" in message
    assert isinstance(caught.value, HevvalError)
    after = sorted(folder.glob("*.json")) if folder.exists() else []
    assert after == before
    assert [r["model_version"] for r in HistoryStore(folder).records()] == (
        ["before"] if before else []
    )
    if folder.exists():
        assert list(folder.glob(".tmp-*")) == []


# --------------------------------------------------------------------------------------------
# Determinism

PACK = """\
name: pack
reference: {path: ref.parquet, time: t}
model: {path: sim.parquet, time: time}
alignment: {max_lag_s: 2}
thresholds: {mae: 0.97, rms: 0.95}
min_phi: 0.5
sets:
  - signal: E
    ref: integrate(V * I) / 3600
    sim: integrate(P) / 3600
    children:
      - signal: P
        ref: V * I
        children:
          - {signal: V, alpha: 0.5}
          - {signal: I, alpha: 0.5}
  - {signal: speed}
"""


def _write_pack(folder: Path, *, fault: bool = False, n: int = 1200, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    voltage = 350 + 10 * np.sin(t / 13)
    current = 60 + 50 * np.sin(t / 5)
    speed = 40 + 30 * np.sin(t / 20)
    sim_voltage = voltage + rng.normal(0, 0.05, n)
    sim_current = current + rng.normal(0, 0.05, n)
    if fault:
        sim_current = sim_current * 1.25 + 8.0
    pd.DataFrame({"t": t, "V": voltage, "I": current, "speed": speed}).to_parquet(
        folder / "ref.parquet"
    )
    pd.DataFrame(
        {
            "time": t,
            "V": sim_voltage,
            "I": sim_current,
            "P": sim_voltage * sim_current,
            "speed": speed + rng.normal(0, 0.2, n),
        }
    ).to_parquet(folder / "sim.parquet")


def _result_text(spec: Any, workers: int) -> str:
    return json.dumps(evaluate_spec(spec, workers=workers).result.to_dict())


@pytest.mark.parametrize("fault", [False, True])
def test_results_are_bit_identical_across_runs_and_workers(tmp_path: Path, fault: bool) -> None:
    _write_pack(tmp_path, fault=fault)
    (tmp_path / "pack.hevval.yaml").write_text(PACK)
    spec = load_spec(tmp_path / "pack.hevval.yaml")
    texts = [_result_text(spec, workers) for workers in (1, 2, 1, 2)]
    assert texts[0] == texts[1] == texts[2] == texts[3]
    reloaded = load_spec(tmp_path / "pack.hevval.yaml")
    assert _result_text(reloaded, 2) == texts[0]


def test_long_single_signal_is_bit_identical_across_workers(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    n = 600_000
    reference = rng.normal(size=n)
    _write_pair(tmp_path, reference, reference + rng.normal(0, 0.3, n))
    spec = _spec(tmp_path, ONE)
    assert _result_text(spec, 1) == _result_text(spec, 2)


def test_reports_are_byte_identical_across_runs(tmp_path: Path) -> None:
    from pytest_hevval.report.writer import write_reports

    _write_pack(tmp_path, fault=True)
    (tmp_path / "pack.hevval.yaml").write_text(PACK)
    contents = []
    for run in ("a", "b"):
        spec = load_spec(tmp_path / "pack.hevval.yaml")
        result = evaluate_spec(spec, figures=True, workers=2).result
        paths = write_reports(
            [result],
            {"json", "md", "html"},
            tmp_path / run,
            generated_utc="2024-05-01 12:00:00 UTC",
        )
        contents.append({p.name: p.read_bytes() for p in paths})
    assert set(contents[0]) == {"report.json", "report.md", "report.html"}
    assert contents[0] == contents[1]


# Plugins the inner runs do not need; each xdist worker would import them again.
QUIET = ("--hevval", "-p", "xdist", "-p", "no:hypothesispytest", "-p", "no:cacheprovider")
QUIET = ("--hevval-history", *QUIET, "--continue-on-collection-errors")

DEGENERATE_SPEC = """\
reference: {path: flat.parquet}
model: {path: flat.parquet}
sets:
  - {signal: v}
"""


def _junit_cases(path: Path) -> dict[str, tuple[str, dict[str, str | None], str]]:
    cases = {}
    for case in ET.parse(path).iter("testcase"):
        outcome = "passed"
        message = ""
        for tag in ("failure", "error", "skipped"):
            element = case.find(tag)
            if element is not None:
                outcome = tag
                message = (element.get("message") or "") + (element.text or "")
        properties = {p.get("name", ""): p.get("value") for p in case.iter("property")}
        name = f"{case.get('classname')}::{case.get('name')}"
        cases[name] = (outcome, properties, message)
    return cases


@pytest.mark.usefixtures("one_kernel_path")
def test_same_outcomes_messages_and_properties_with_and_without_xdist(
    pytester: pytest.Pytester,
) -> None:
    good = pytester.mkdir("good")
    bad = pytester.mkdir("bad")
    _write_pack(good)
    _write_pack(bad, fault=True, seed=3)
    (good / "pack.hevval.yaml").write_text(PACK)
    (bad / "pack.hevval.yaml").write_text(PACK)
    flat = pd.DataFrame({"time": np.arange(50) * 0.1, "v": np.full(50, 2.0)})
    flat.to_parquet(pytester.path / "flat.parquet")
    pytester.makefile(".hevval.yaml", flat=DEGENERATE_SPEC)
    pytester.makefile(".hevval.yaml", broken=PACK.replace("min_phi", "min_phy"))
    serial = pytester.runpytest(*QUIET, "-n", "0", "--junitxml=serial.xml")
    parallel = pytester.runpytest(*QUIET, "-n", "2", "--junitxml=par.xml")
    outcomes = serial.parseoutcomes()
    assert outcomes == parallel.parseoutcomes()
    assert outcomes == {"passed": 9, "failed": 3, "errors": 3}  # errors: flat v, its Φ, broken
    serial_cases = _junit_cases(pytester.path / "serial.xml")
    assert serial_cases == _junit_cases(pytester.path / "par.xml")
    assert len(serial_cases) == 15
    # Both runs were recorded; apart from their start times the records are the same.
    store = HistoryStore(pytester.path / ".hevval" / "history")
    records = store.records()
    assert store.problems == []
    assert len(records) == 2
    assert records[0]["specs"] == records[1]["specs"]
    assert len(records[0]["specs"]) == 2


def test_four_xdist_workers_write_one_intact_history_record(pytester: pytest.Pytester) -> None:
    for index in range(4):
        folder = pytester.mkdir(f"s{index}")
        _write_pack(folder, seed=index, n=300)
        (folder / "pack.hevval.yaml").write_text(PACK)
    pytester.runpytest(*QUIET, "-n", "4").assert_outcomes(passed=24)
    store = HistoryStore(pytester.path / ".hevval" / "history")
    records = store.records()
    assert store.problems == []
    assert len(records) == 1  # only the controller records the run
    assert len(records[0]["specs"]) == 4


# --------------------------------------------------------------------------------------------
# Safety

UNSAFE_TAGS = [
    "!!python/object/apply:os.system ['touch {marker}']",
    "!!python/object/apply:subprocess.call [['touch', '{marker}']]",
    "!!python/object/new:os.system ['touch {marker}']",
    "!!python/name:os.system",
    "!!python/module:os",
    "!!python/object:pathlib.Path {{}}",
]


@pytest.mark.parametrize("tag", UNSAFE_TAGS)
@pytest.mark.parametrize("where", ["reference", "sets[0].ref", "top"])
def test_python_yaml_tags_are_rejected_and_run_nothing(
    tmp_path: Path, tag: str, where: str
) -> None:
    marker = tmp_path / "pwned"
    value = tag.format(marker=marker)
    text = "reference: a.csv\nmodel: b.csv\nsets:\n  - signal: x\n    ref: x\n"
    if where == "reference":
        text = text.replace("reference: a.csv", f"reference: {value}")
    elif where == "sets[0].ref":
        text = text.replace("ref: x", f"ref: {value}")
    else:
        text = f"--- {value}\n"
    spec = tmp_path / "evil.hevval.yaml"
    spec.write_text(text)
    with pytest.raises(
        SpecError, match=r"evil\.hevval\.yaml:\d+: invalid YAML: could not determine"
    ):
        load_spec(spec)
    assert not marker.exists()


def test_spec_yaml_goes_through_the_safe_loader_only() -> None:
    from pytest_hevval.spec import yaml_lines

    assert issubclass(yaml_lines._LineLoader, yaml.SafeLoader)
    assert not issubclass(yaml_lines._LineLoader, (yaml.FullLoader, yaml.UnsafeLoader))
    with pytest.raises(yaml.constructor.ConstructorError):
        load_yaml_with_lines("!!python/object/apply:os.getcwd []")


PACKAGE = Path(pytest_hevval.__file__).parent
FORBIDDEN = [
    (r"^\s*(import|from)\s+(pickle|cPickle|dill|cloudpickle|shelve|marshal)\b", "pickle import"),
    (r"\b(pickle|dill|cloudpickle|marshal)\.(loads?|Unpickler)\b", "unpickling"),
    (r"allow_pickle\s*=\s*True", "numpy allow_pickle"),
    (r"\bread_pickle\b", "pandas read_pickle"),
    (r"\byaml\.(unsafe_load|full_load|load_all)\b", "unsafe YAML loading"),
    (r"\b(FullLoader|UnsafeLoader|yaml\.Loader)\b", "unsafe YAML loader"),
    (r"\byaml\.load\((?![^)]*Loader=_LineLoader)", "yaml.load without the safe line loader"),
    (r"(?<![\w.])(eval|exec)\(", "eval/exec"),
]


def test_package_never_unpickles_or_loads_yaml_unsafely() -> None:
    sources = sorted(PACKAGE.rglob("*.py"))
    assert len(sources) > 20
    found = []
    for path in sources:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            code = line.split("#", 1)[0]
            for pattern, what in FORBIDDEN:
                if re.search(pattern, code):
                    found.append(f"{path.relative_to(PACKAGE)}:{number}: {what}: {line.strip()}")
    assert found == []


def test_forbidden_patterns_do_match_what_they_forbid() -> None:
    samples = {
        "import pickle": "pickle import",
        "    from pickle import loads": "pickle import",
        "data = pickle.load(handle)": "unpickling",
        "np.load(path, allow_pickle=True)": "numpy allow_pickle",
        "yaml.load(text, Loader=yaml.Loader)": "unsafe YAML loader",
        "yaml.load(text)": "yaml.load without the safe line loader",
        "value = eval(source)": "eval/exec",
    }
    for line, what in samples.items():
        assert any(re.search(p, line) and w == what for p, w in FORBIDDEN), line
    assert not any(re.search(p, "yaml.load(text, Loader=_LineLoader)") for p, _ in FORBIDDEN)
    assert not any(re.search(p, "ast.literal_eval(x)") for p, _ in FORBIDDEN)


CALLABLE_SPEC = """\
reference: ref.parquet
model: {callable: "side_effect_model:run", params: {gain: 1.0}, driven_by: [v]}
sets:
  - {signal: v}
"""

SIDE_EFFECT_MODEL = """
from pathlib import Path
Path(__file__).with_name("imported").write_text("yes")

def run(frame, gain):
    Path(__file__).with_name("ran").write_text("yes")
    return frame.assign(v=frame["v"] * gain)
"""


def test_model_callable_runs_only_when_evaluated(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    # (expressions never reach eval: tests/test_expressions.py::test_never_evaluates_python)
    pytester.makepyfile(side_effect_model=SIDE_EFFECT_MODEL)
    _write_pair(pytester.path, BASE, NEAR)
    (pytester.path / "model.hevval.yaml").write_text(CALLABLE_SPEC)
    imported = pytester.path / "imported"
    ran = pytester.path / "ran"
    spec = load_spec(pytester.path / "model.hevval.yaml")
    assert spec.model.callable == "side_effect_model:run"
    pytester.runpytest(*QUIET[:-1], "--collect-only").assert_outcomes()
    assert not imported.exists()
    assert not ran.exists()
    monkeypatch.delitem(sys.modules, "side_effect_model", raising=False)
    result = evaluate_spec(spec).result
    monkeypatch.delitem(sys.modules, "side_effect_model")
    assert ran.read_text() == "yes"
    assert result.data.model.kind == "callable"


def test_file_models_never_start_a_callable_or_fmu(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pytest_hevval.data import fmu, models

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("a model ran although the spec names only files")

    monkeypatch.setattr(models, "run_callable", refuse)
    monkeypatch.setattr(models, "import_callable", refuse)
    monkeypatch.setattr(fmu, "run_fmu", refuse)
    _write_pair(tmp_path, BASE, NEAR)
    candidates = 'candidates: {c: "`v` * 2"}\n'
    result = evaluate_spec(_spec(tmp_path, ONE, candidates)).result
    assert result.data.model.kind == "file"


def test_spec_parsing_imports_no_model(tmp_path: Path) -> None:
    text = CALLABLE_SPEC.replace("side_effect_model", "module_that_does_not_exist")
    spec = parse_spec_text(text, tmp_path / "model.hevval.yaml")
    assert "module_that_does_not_exist" not in sys.modules
    assert spec.model.kind == "callable"
    fmu_text = CALLABLE_SPEC.replace(
        '{callable: "side_effect_model:run", params: {gain: 1.0}, driven_by: [v]}',
        "{fmu: missing.fmu}",
    )
    assert parse_spec_text(fmu_text, tmp_path / "fmu.hevval.yaml").model.kind == "fmu"
