"""The reader registry, third-party readers, and the byte-level guards on plain bytes."""

from __future__ import annotations

import io
import struct
from collections.abc import Iterable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pytest_hevval.data import readers
from pytest_hevval.data.readers import format_names, read_record, register_reader
from pytest_hevval.data.readers.guards.mat5 import mat5_problem_in
from pytest_hevval.data.readers.guards.mdf import mdf_loop_in
from pytest_hevval.data.record import Channel, Record, SourceOptions
from pytest_hevval.errors import HevvalError, SpecError
from pytest_hevval.spec.load import parse_spec_text


def _read_xyz(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    """A toy format: one number per line, sampled at 1 Hz, channel 'x'."""
    values = np.array([float(v) for v in Path(path).read_text().split()], dtype=np.float64)
    time = np.arange(values.shape[0], dtype=np.float64)
    return Record(source=path, channels={"x": Channel(time, values)}, available=("x",))


@pytest.fixture
def xyz_reader(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(readers, "_READERS", dict(readers._READERS))
    monkeypatch.setattr(readers, "FORMATS", dict(readers.FORMATS))
    register_reader("xyz", _read_xyz, [".xyz"])


SPEC = """
name: toy
reference: {{path: data.xyz{fmt}}}
model: {{path: data.xyz{fmt}}}
sets:
  - {{signal: x, ref: x}}
"""


@pytest.mark.usefixtures("xyz_reader")
def test_a_registered_reader_is_a_format_the_spec_accepts(tmp_path: Path) -> None:
    (tmp_path / "data.xyz").write_text("1 2 3 4 5\n")
    spec = parse_spec_text(SPEC.format(fmt=", format: xyz"), tmp_path / "t.hevval.yaml")
    assert spec.reference.options.format == "xyz"
    record = read_record(str(tmp_path / "data.xyz"), ["x"], spec.reference.options)
    assert record.channels["x"].values.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert record.meta["format"] == "xyz"
    # Chosen by its extension too.
    assert read_record(str(tmp_path / "data.xyz"), None, SourceOptions()).meta["format"] == "xyz"


def test_an_unregistered_format_is_a_spec_error_with_a_suggestion(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"reference\.format: must be one of csv") as caught:
        parse_spec_text(SPEC.format(fmt=", format: parquett"), tmp_path / "t.hevval.yaml")
    assert "did you mean 'parquet'" in str(caught.value)


def test_aliases_stay_accepted(tmp_path: Path) -> None:
    spec = parse_spec_text(SPEC.format(fmt=", format: mf4"), tmp_path / "t.hevval.yaml")
    assert spec.reference.options.format == "mf4"
    assert {"mf4", "h5", "pq"} <= set(format_names())


def _entry_points(*entries: SimpleNamespace) -> object:
    def select(*, group: str) -> list[SimpleNamespace]:
        return [e for e in entries if group == readers.ENTRY_POINT_GROUP]

    return select


@pytest.mark.usefixtures("xyz_reader")
def test_a_reader_entry_point_is_loaded_once(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[str] = []

    def register() -> None:
        calls.append("registered")
        register_reader("abc", _read_xyz, [".abc"])

    entry = SimpleNamespace(name="abc", value="abc_reader:register", load=lambda: register)
    monkeypatch.setattr("importlib.metadata.entry_points", _entry_points(entry))
    monkeypatch.setattr(readers, "_ENTRY_POINTS_LOADED", False)
    assert "abc" in format_names()
    assert "abc" in format_names()
    assert calls == ["registered"]


def test_a_broken_reader_entry_point_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken() -> None:
        raise ImportError("No module named 'vendor_format'")

    entry = SimpleNamespace(name="vendor", value="vendor_format:register", load=broken)
    monkeypatch.setattr("importlib.metadata.entry_points", _entry_points(entry))
    monkeypatch.setattr(readers, "_ENTRY_POINTS_LOADED", False)
    with pytest.raises(HevvalError, match="the reader entry point 'vendor'") as caught:
        format_names()
    assert "vendor_format:register" in str(caught.value)
    assert "pytest_hevval.readers" in str(caught.value)


MS_ROWS = "".join(f"{i * 100},{i}\n" for i in range(1000))


def test_check_time_unit_is_a_real_spec_key(tmp_path: Path) -> None:
    (tmp_path / "a.csv").write_text("time,v\n" + MS_ROWS)
    text = SPEC.replace("data.xyz{fmt}", "a.csv{fmt}").replace("x, ref: x", "v, ref: v")
    spec = parse_spec_text(text.format(fmt=", check_time_unit: false"), tmp_path / "t.hevval.yaml")
    record = read_record(str(tmp_path / "a.csv"), ["v"], spec.reference.options)
    assert record.channels["v"].time[-1] == 99900.0
    default = parse_spec_text(text.format(fmt=""), tmp_path / "t.hevval.yaml")
    with pytest.raises(HevvalError, match="time looks like milliseconds"):
        read_record(str(tmp_path / "a.csv"), ["v"], default.reference.options)
    with pytest.raises(SpecError, match="check_time_unit: must be true or false"):
        parse_spec_text(text.format(fmt=", check_time_unit: maybe"), tmp_path / "t.hevval.yaml")


# -- guards on plain bytes --------------------------------------------------------------------


def _mat5(*elements: bytes) -> bytes:
    header = b"MATLAB 5.0 MAT-file".ljust(116, b" ") + bytes(8) + struct.pack("<H", 0x0100) + b"IM"
    return header + b"".join(elements)


def test_mat5_guard_on_bytes() -> None:
    # A well-formed top level: one 8-byte double element (type 9) — nothing to refuse.
    assert mat5_problem_in(_mat5(struct.pack("<II", 9, 8) + bytes(8))) is None
    # Type 99 does not exist: scipy would index its type table out of bounds.
    problem = mat5_problem_in(_mat5(struct.pack("<II", 99, 8) + bytes(8)))
    assert problem is not None
    assert "undefined data type 99 at byte 128" in problem
    # Not MAT v5 at all: left to scipy.
    assert mat5_problem_in(b"\x00" * 200) is None


def _mdf4_with_self_linked_group() -> bytes:
    # Identification block (64 bytes) with version 4.10, then a header block whose first
    # data-group link (at byte 64 + 24 = 88) points at a block that links to itself.
    ident = b"MDF     4.10    ".ljust(64, b"\x00")
    head = bytearray(ident + bytes(200))
    data_group = 128
    struct.pack_into("<Q", head, 88, data_group)
    struct.pack_into("<Q", head, data_group + 24, data_group)  # next data group → itself
    return bytes(head)


def test_mdf_guard_on_bytes() -> None:
    damaged = _mdf4_with_self_linked_group()
    assert mdf_loop_in(io.BytesIO(damaged), len(damaged)) == (
        "the block at byte 128 is linked to twice (a loop)"
    )
    intact = bytearray(damaged)
    struct.pack_into("<Q", intact, 128 + 24, 0)  # the list ends after one group
    assert mdf_loop_in(io.BytesIO(bytes(intact)), len(intact)) is None
    assert mdf_loop_in(io.BytesIO(b"not an mdf file" * 10), 150) is None
