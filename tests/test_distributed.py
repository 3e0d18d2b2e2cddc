"""Specs evaluated on Dask equal the local engine's results; data read through fsspec URLs."""

from __future__ import annotations

import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.data.remote import is_url, local_copy, parquet_source
from pytest_hevval.errors import DataError, HevvalError, SpecError
from pytest_hevval.scoring.cluster import (
    FREE_PORT,
    error_from_payload,
    error_payload,
    evaluate_on_dask,
    is_error_payload,
)
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import load_spec

distributed = pytest.importorskip("distributed")
fsspec = pytest.importorskip("fsspec")

#: How close a worker's result must be to the local one. A worker process does not run with
#: this process's settings (a dask nanny starts it with one BLAS thread, for one), and CI has
#: seen a bootstrap bound differ in its last bit (0.9999997118182162 against ...156).
ROUNDING = 1e-12


def same_result(found: Any, expected: Any) -> bool:
    """Equal, with floats equal to :data:`ROUNDING` relative (NaN equals NaN)."""
    if isinstance(expected, dict):
        return (
            isinstance(found, dict)
            and found.keys() == expected.keys()
            and all(same_result(found[k], expected[k]) for k in expected)
        )
    if isinstance(expected, list | tuple):
        return (
            isinstance(found, list | tuple)
            and len(found) == len(expected)
            and all(same_result(a, b) for a, b in zip(found, expected, strict=True))
        )
    if isinstance(expected, float) and not isinstance(found, bool):
        return isinstance(found, int | float) and (
            found == pytest.approx(expected, rel=ROUNDING, abs=ROUNDING, nan_ok=True)
        )
    return bool(found == expected)


def test_same_result_tells_rounding_from_a_difference() -> None:
    assert same_result({"a": [1.0, {"b": float("nan")}]}, {"a": [1.0 + 1e-15, {"b": float("nan")}]})
    assert not same_result({"a": [1.0]}, {"a": [1.0 + 1e-9]})
    assert not same_result({"a": 1.0}, {"a": 1.0, "b": 2})
    assert not same_result({"a": "x"}, {"a": "y"})
    assert not same_result([1.0, 2.0], [1.0])


TREE = """\
sets:
  - signal: P
    ref: V * I
    sim: P
    children:
      - {signal: V}
      - {signal: I}
  - {signal: speed, interpolation: previous}
"""


def _frames(seed: int, *, duration_s: float = 60.0) -> tuple[pd.DataFrame, pd.DataFrame]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.1)
    voltage = 350 + 10 * np.sin(t / 7 + seed)
    current = 60 + 50 * np.sin(t / 3)
    speed = 40 + 30 * np.sin(t / 11)
    sim_v = voltage + rng.normal(0, 0.3, t.size)
    sim_i = np.roll(current, 2) + rng.normal(0, 0.5, t.size)
    reference = pd.DataFrame({"t": t, "V": voltage, "I": current, "speed": speed})
    model = pd.DataFrame(
        {"time": t, "V": sim_v, "I": sim_i, "P": sim_v * sim_i, "speed": speed + 0.2}
    )
    return reference, model


def _spec_text(name: str, reference: str, model: str) -> str:
    return (
        f"name: {name}\n"
        f"reference: {{path: {reference}, time: t}}\n"
        f"model: {{path: {model}, time: time}}\n"
        "alignment: {max_lag_s: 1}\n"
        "thresholds: {mae: 0.9}\n" + TREE
    )


@pytest.fixture
def memory_root() -> Iterator[str]:
    """A private folder of fsspec's in-process memory file system, removed afterwards."""
    root = f"memory://hevval-{uuid.uuid4().hex}"
    yield root
    filesystem = fsspec.filesystem("memory")
    if filesystem.exists(root):
        filesystem.rm(root, recursive=True)


def _write_memory(url: str, data: bytes) -> None:
    with fsspec.open(url, "wb") as handle:
        handle.write(data)


@pytest.fixture
def specs(tmp_path: Path, memory_root: str) -> list[Path]:
    """Three good specs (CSV, Parquet, fsspec URLs) and two bad ones, in a fixed order."""
    data = tmp_path / "data"
    data.mkdir()
    ref_a, sim_a = _frames(1)
    ref_a.to_csv(data / "ref_a.csv", index=False)
    sim_a.to_csv(data / "sim_a.csv", index=False)
    ref_b, sim_b = _frames(2, duration_s=90.0)
    ref_b.to_parquet(data / "ref_b.parquet", index=False)
    sim_b.to_parquet(data / "sim_b.parquet", index=False)
    ref_c, sim_c = _frames(3)
    # Parquet through a URL is streamed, CSV through a URL is copied first: both paths.
    _write_memory(f"{memory_root}/ref_c.parquet", ref_c.to_parquet(index=False))
    _write_memory(f"{memory_root}/sim_c.csv", sim_c.to_csv(index=False).encode())

    texts = {
        "a.hevval.yaml": _spec_text("a", "data/ref_a.csv", "data/sim_a.csv"),
        "b.hevval.yaml": _spec_text("b", "data/ref_b.parquet", "data/sim_b.parquet"),
        "c.hevval.yaml": _spec_text(
            "c", f"{memory_root}/ref_c.parquet", f"{memory_root}/sim_c.csv"
        ),
        "bad_key.hevval.yaml": _spec_text("bad", "data/ref_a.csv", "data/sim_a.csv").replace(
            "thresholds:", "threshold:"
        ),
        "bad_column.hevval.yaml": _spec_text("bad", "data/ref_a.csv", "data/sim_a.csv").replace(
            "{signal: V}", "{signal: V, ref: Volts}"
        ),
    }
    paths = []
    for name, text in texts.items():
        path = tmp_path / name
        path.write_text(text)
        paths.append(path)
    return paths


def _local(path: Path, rootdir: Path) -> dict[str, Any]:
    return evaluate_spec(load_spec(path), rootdir=rootdir).result.to_dict()


def _local_error(path: Path, rootdir: Path) -> HevvalError:
    with pytest.raises(HevvalError) as info:
        _local(path, rootdir)
    return info.value


@pytest.fixture
def cluster() -> Iterator[Any]:
    # In-process workers: they share this process's memory:// file system, and start fast.
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=FREE_PORT
    ) as local:
        yield local


def test_dask_results_equal_local_results(specs: list[Path], tmp_path: Path, cluster: Any) -> None:
    # The local results first: the cluster's workers are threads of this process, and the
    # package's modules, imported here, are parsed by pytest's assertion rewriter, which on
    # Python 3.11 can fail when two threads parse at once (two specs' first imports).
    expected = [_local(path, tmp_path) for path in specs[:3]]
    expected_errors = [_local_error(path, tmp_path) for path in specs[3:]]
    counts: list[int] = []
    results = evaluate_on_dask(
        specs, cluster.scheduler_address, rootdir=tmp_path, progress=counts.append
    )

    assert len(results) == len(specs)
    assert counts == [1, 2, 3, 4, 5]
    bad = specs[3:]
    for result, local in zip(results[:3], expected, strict=True):
        assert not is_error_payload(result)
        assert same_result(result, local)
    assert [r["name"] for r in results[:3]] == ["a", "b", "c"]
    assert results[2]["data"]["reference"]["path"].startswith("memory://")

    for path, payload, local_error in zip(bad, results[3:], expected_errors, strict=True):
        assert is_error_payload(payload)
        assert payload["spec"] == str(path)
        error = error_from_payload(payload)
        assert type(error) is type(local_error)
        assert str(error) == str(local_error) == payload["error"]
    assert isinstance(error_from_payload(results[3]), SpecError)
    assert isinstance(error_from_payload(results[4]), DataError)
    assert "Volts" in results[4]["error"]


def test_no_specs_needs_no_cluster(tmp_path: Path) -> None:
    assert evaluate_on_dask([], "tcp://192.0.2.1:1", rootdir=tmp_path) == []


def test_error_payload_round_trip_is_json_safe() -> None:
    import json

    error = DataError("no such column", file="x.csv", line=3, column="V", hint="check it")
    payload = json.loads(json.dumps(error_payload("s.hevval.yaml", error)))
    back = error_from_payload(payload)
    assert type(back) is DataError
    assert str(back) == str(error)
    assert (back.file, back.line, back.column) == ("x.csv", 3, "V")
    # A payload with only the documented fields still becomes the right class.
    minimal = error_from_payload({"spec": "s", "error": "broken", "kind": "SpecError"})
    assert type(minimal) is SpecError
    assert "broken" in str(minimal)


@pytest.mark.parametrize(
    ("path", "expected"),
    [
        ("s3://bucket/trip.parquet", True),
        ("memory://x/y.csv", True),
        ("simplecache::s3://bucket/trip.csv", True),
        ("file:///data/trip.csv", True),
        ("/data/trip.csv", False),
        ("C:\\data\\trip.csv", False),
        ("data/odd://name.csv", False),
    ],
)
def test_is_url(path: str, expected: bool) -> None:
    assert is_url(path) is expected


def test_url_errors_name_the_url_not_a_temporary_file(memory_root: str) -> None:
    url = f"{memory_root}/ref.csv"
    _write_memory(url, b"t,V\n0,1\n0.1,2\n0.2,3\n")
    record = read_record(url, ["V"], SourceOptions())
    assert record.source == url
    assert record.channels["V"].values.tolist() == [1.0, 2.0, 3.0]

    with pytest.raises(DataError) as info:
        read_record(url, ["Volts"], SourceOptions())
    assert info.value.file == url
    assert str(info.value).startswith(f"{url}: column 'Volts': no such column")
    assert tempfile.gettempdir() not in str(info.value)

    with pytest.raises(DataError, match="file not found") as missing:
        read_record(f"{memory_root}/nope.parquet", None, SourceOptions())
    assert missing.value.file == f"{memory_root}/nope.parquet"

    _write_memory(f"{memory_root}/empty.csv", b"")
    with pytest.raises(DataError, match="empty"):
        read_record(f"{memory_root}/empty.csv", None, SourceOptions())


def test_parquet_url_reads_only_wanted_columns(memory_root: str) -> None:
    frame = pd.DataFrame({"time": [0.0, 0.5, 1.0], "a": [1.0, 2.0, 3.0], "b": [4, 5, 6]})
    url = f"{memory_root}/trip.parquet"
    _write_memory(url, frame.to_parquet(index=False))
    record = read_record(url, ["b"], SourceOptions())
    assert list(record.channels) == ["b"]
    assert record.available == ("time", "a", "b")
    assert record.channels["b"].time.tolist() == [0.0, 0.5, 1.0]
    assert record.source == url

    source, filesystem = parquet_source(url)
    assert filesystem is not None
    assert "://" not in source
    assert parquet_source("/local/trip.parquet") == ("/local/trip.parquet", None)


def test_unknown_protocol_is_a_data_error() -> None:
    with pytest.raises(DataError, match="cannot open this URL") as info:
        read_record("nosuchprotocol://bucket/trip.csv", None, SourceOptions())
    assert info.value.file == "nosuchprotocol://bucket/trip.csv"


def test_local_copy_keeps_the_name_and_cleans_up(memory_root: str) -> None:
    url = f"{memory_root}/folder/trip.mf4"
    _write_memory(url, b"not really mdf")
    with local_copy(url) as local:
        assert Path(local).name == "trip.mf4"
        assert Path(local).read_bytes() == b"not really mdf"
    assert not Path(local).exists()


def test_local_address_starts_and_stops_a_cluster(
    specs: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[tuple[dict[str, Any], Any]] = []
    real = distributed.LocalCluster

    def in_process(**kwargs: Any) -> Any:
        # Worker processes take seconds to spawn; the wiring is what is under test here.
        cluster = real(**{**kwargs, "processes": False, "n_workers": 1})
        started.append((kwargs, cluster))
        return cluster

    monkeypatch.setattr(distributed, "LocalCluster", in_process)
    results = evaluate_on_dask(specs[:2], "local", rootdir=tmp_path)

    assert same_result(results, [_local(path, tmp_path) for path in specs[:2]])
    [(kwargs, cluster)] = started
    assert kwargs["processes"] is True
    assert kwargs["dashboard_address"] == FREE_PORT
    assert cluster.status.name == "closed"


def test_scheduler_file_address(specs: list[Path], tmp_path: Path, cluster: Any) -> None:
    import json

    scheduler_file = tmp_path / "scheduler.json"
    scheduler_file.write_text(json.dumps({"address": cluster.scheduler_address}))
    results = evaluate_on_dask(specs[:1], str(scheduler_file), rootdir=tmp_path)
    assert same_result(results, [_local(specs[0], tmp_path)])


def test_unreachable_scheduler_is_a_hevval_error(specs: list[Path], tmp_path: Path) -> None:
    import socket

    import dask

    # A port that was free a moment ago: nothing answers there.
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with (
        dask.config.set({"distributed.comm.timeouts.connect": "1s"}),
        pytest.raises(HevvalError, match="cannot connect to the Dask scheduler") as info,
    ):
        evaluate_on_dask(specs[:1], f"tcp://127.0.0.1:{port}", rootdir=tmp_path)
    assert f"127.0.0.1:{port}" in str(info.value)


CRASHING_MODEL = """\
import os


def model(frame, **params):
    os._exit(3)
"""


def test_a_worker_that_dies_costs_only_its_spec(specs: list[Path], tmp_path: Path) -> None:
    import dask

    (tmp_path / "crashing.py").write_text(CRASHING_MODEL)
    crash = tmp_path / "crash.hevval.yaml"
    crash.write_text(
        "reference: {path: data/ref_a.csv, time: t}\n"
        "model: {callable: 'crashing:model'}\n"
        "sets:\n  - {signal: V}\n"
    )
    # Give up on a task after one death. Two idle workers take one spec each: a death also
    # counts against every task queued on the same worker.
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 0}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=FREE_PORT
        ) as local,
    ):
        results = evaluate_on_dask([crash, specs[0]], local.scheduler_address, rootdir=tmp_path)
    assert is_error_payload(results[0])
    assert "worker evaluating this spec died" in results[0]["error"]
    assert type(error_from_payload(results[0])) is HevvalError
    assert same_result(results[1], _local(specs[0], tmp_path))
