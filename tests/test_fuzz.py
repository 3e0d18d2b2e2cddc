"""Fuzzing the three places untrusted text and bytes enter: specs, expressions and data files.

Every input must end in exactly one of two ways: a result, or a HevvalError whose message names
the file (and the key or column where there is one). Any other exception is a bug.

The default budget keeps this file to a few seconds. ``HEVVAL_FUZZ_EXAMPLES=N`` runs N examples
per target instead; ``--hypothesis-show-statistics`` prints how many inputs each target tried
and how they ended (see docs/reliability.md for the recorded large runs).
"""

from __future__ import annotations

import contextlib
import copy
import gc
import io
import json
import os
import struct
import subprocess
import sys
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.extra import numpy as hnp

from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import Record, SourceOptions
from pytest_hevval.errors import DataError, ExpressionError, SpecError
from pytest_hevval.spec.expressions import FUNCTIONS, parse_signal
from pytest_hevval.spec.load import load_spec, parse_spec_text

_BUDGET = int(os.environ.get("HEVVAL_FUZZ_EXAMPLES", "0") or 0)


def budget(default: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Hypothesis settings for one fuzz target: ``default`` examples unless the env says more."""
    return settings(
        max_examples=_BUDGET or default,
        deadline=None,
        suppress_health_check=[
            HealthCheck.too_slow,
            HealthCheck.data_too_large,
            HealthCheck.filter_too_much,
        ],
    )


def _note(outcome: str) -> None:
    """Count an outcome for ``--hypothesis-show-statistics``; a no-op outside a fuzz target."""
    with contextlib.suppress(InvalidArgument):
        event(outcome)


SPEC_PATH = Path("/project/specs/trip.hevval.yaml")


def _spec_outcome(text: str, path: Path = SPEC_PATH) -> None:
    """Parse ``text``; a SpecError must name the file, anything but a Spec or SpecError fails."""
    try:
        spec = parse_spec_text(text, path)
    except SpecError as exc:
        error = exc
    else:
        _note("Spec")
        assert spec.sets
        return
    _note("SpecError")
    assert str(error).startswith(str(path)), str(error)
    if error.key:
        assert f"{error.key}: " in str(error)


# --------------------------------------------------------------------------------------------
# Spec parser


VALID_SPEC: dict[str, Any] = {
    "name": "pack",
    "description": "a battery pack on a WLTP trip",
    "reference": {"path": "data/ref.csv", "time": "t", "sep": ",", "time_scale": 1.0},
    "model": {"path": "data/sim.csv", "time": "time"},
    "alignment": {
        "max_lag_s": 2,
        "rate_hz": 10,
        "window": [0, 10],
        "offset_from": {"ref": "V", "sim": "V"},
        "nan": "omit",
    },
    "thresholds": {"mae": 0.97, "lambda4": 0.95},
    "weights": {"mae": 2, "rms": 1},
    "min_phi": 0.5,
    "correlation": "xcorr",
    "emergent": "V2",
    "candidates": {"ambient": "`T amb` * 2"},
    "sets": [
        {
            "signal": "E",
            "ref": "integrate(V * I) / 3600",
            "sim": "integrate(P) / 3600",
            "unit": "Wh",
            "thresholds": {"rms": 0.5},
            "reference_range": 3,
            "interpolation": "previous",
            "children": [
                {
                    "signal": "P",
                    "ref": "V * I",
                    "children": [{"signal": "V", "alpha": 0.5}, {"signal": "I"}],
                }
            ],
        },
        {"signal": "speed", "unit": "km/h", "ref_scale": 2, "sim_offset": 1},
    ],
}


def _key_paths(value: Any, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    yield prefix
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _key_paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _key_paths(item, (*prefix, index))


KEY_PATHS = list(_key_paths(VALID_SPEC))[1:]

SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=10**300, max_value=10**1000),
    st.floats(),
    st.text(max_size=12),
    st.sampled_from(
        [
            "",
            "nan",
            "1e999",
            "é☃\u202e",
            "a/b",
            "a::b",
            "`x",
            "__import__('os').system('true')",
            "lambda1",
            "x" * 3000,
            "\x00",
        ]
    ),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3),
        st.dictionaries(st.one_of(st.text(max_size=8), st.integers()), inner, max_size=3),
    ),
    max_leaves=8,
)
MUTATIONS = st.lists(
    st.tuples(
        st.sampled_from(KEY_PATHS),
        st.sampled_from(["replace", "delete", "unknown key", "nest"]),
        VALUES,
    ),
    min_size=1,
    max_size=4,
)


def _mutate(document: dict[str, Any], path: tuple[Any, ...], operation: str, value: Any) -> None:
    parent: Any = document
    for part in path[:-1]:
        parent = parent[part]
    last = path[-1]
    if operation == "replace":
        parent[last] = value
    elif operation == "delete":
        del parent[last]
    elif operation == "unknown key" and isinstance(parent[last], dict):
        parent[last]["zz_unknown"] = value
    elif operation == "nest":
        nested = parent[last]
        for _ in range(40):
            nested = {"signal": "n", "children": [nested]} if isinstance(nested, dict) else [nested]
        parent[last] = nested


@given(MUTATIONS)
@budget(150)
def test_structured_spec_mutations(mutations: list[tuple[tuple[Any, ...], str, Any]]) -> None:
    document = copy.deepcopy(VALID_SPEC)
    for path, operation, value in mutations:
        # An earlier mutation may have removed or replaced this path.
        with contextlib.suppress(KeyError, IndexError, TypeError):
            _mutate(document, path, operation, value)
    _spec_outcome(yaml.safe_dump(document, allow_unicode=True))


VALID_TEXT = yaml.safe_dump(VALID_SPEC, sort_keys=False)
VALID_LINES = VALID_TEXT.splitlines(keepends=True)
YAML_TOKENS = [
    *"abc:{}[]-,'\"!&*|>#%@` \n\t0123456789.e+?~",
    "reference",
    "model",
    "sets",
    "signal",
    "children",
    "!!python/object/apply:os.system",
    "!!timestamp",
    "!!int",
    "!!binary",
    "<<",
    "2001-13-01",
    "9" * 5000,
    "\u2028",
    "\x00",
    "\ufeff",
    "\ud800",
]


@st.composite
def text_mutations(draw: st.DrawFn) -> str:
    lines = list(VALID_LINES)
    for _ in range(draw(st.integers(1, 4))):
        index = draw(st.integers(0, len(lines) - 1))
        operation = draw(st.sampled_from(["delete", "duplicate", "insert", "indent", "cut"]))
        if operation == "delete":
            del lines[index]
        elif operation == "duplicate":
            lines.insert(index, lines[index])
        elif operation == "insert":
            line = lines[index]
            at = draw(st.integers(0, len(line)))
            token = draw(st.sampled_from(YAML_TOKENS))
            lines[index] = line[:at] + token + line[at:]
        elif operation == "indent":
            lines[index] = " " * draw(st.integers(0, 7)) + lines[index].lstrip(" ")
        else:
            lines = lines[:index]
        if not lines:
            break
    return "".join(lines)


@given(text_mutations())
@budget(150)
def test_spec_text_mutations(text: str) -> None:
    _spec_outcome(text)


@given(st.lists(st.sampled_from(YAML_TOKENS), max_size=60).map("".join))
@budget(150)
def test_yaml_ish_token_soup(text: str) -> None:
    _spec_outcome(text)


@given(st.binary(max_size=400))
@budget(50)
def test_spec_file_bytes(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    path = tmp_path_factory.getbasetemp() / "bytes.hevval.yaml"
    path.write_bytes(data)
    try:
        load_spec(path)
    except SpecError as exc:
        error = exc
    else:
        return
    assert str(error).startswith(str(path))


def _nested_signals(depth: int) -> str:
    lines = ["reference: a.csv", "model: b.csv", "sets:"]
    for level in range(depth):
        pad = "  " * level
        lines += [f"{pad}  - signal: s{level}", f"{pad}    children:"]
    lines.append("  " * depth + "  - signal: leaf")
    return "\n".join(lines) + "\n"


MINIMAL = "reference: a.csv\nmodel: b.csv\nsets: [{signal: x}]\n"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[" * 5000 + "]" * 5000, "trip.hevval.yaml: invalid YAML: nested too deeply"),
        ("{a: " * 3000 + "1" + "}" * 3000, "invalid YAML: nested too deeply"),
        (_nested_signals(300), "invalid YAML: nested too deeply"),
        (
            "a: " + "9" * 5000 + "\n",
            "trip.hevval.yaml:1: invalid YAML: cannot read this value as int",
        ),
        ("reference: 2001-13-01\n", ":1: invalid YAML: cannot read this value as timestamp"),
        ("x: 1\ny: 2001-02-28t25:00:00\n", ":2: invalid YAML: cannot read this value as timestamp"),
        ("a: !!int 0x\n", ":1: invalid YAML: cannot read this value as int"),
        ("a: !!bool maybe\n", ":1: invalid YAML: cannot read this value as bool"),
        ("a: !!timestamp x\n", ":1: invalid YAML: cannot read this value as timestamp"),
        ("a: !!map [1]\n", ":1: invalid YAML: cannot read this value as map"),
        ("a: !!seq {a: 1}\n", ":1: invalid YAML: cannot read this value as seq"),
        ("reference: &r [*r]\n", ":1: invalid YAML: an alias refers to the value that holds it"),
        (
            MINIMAL.replace("x}", "x, alpha: " + "9" * 400 + "}"),
            ":3: sets[0].alpha: must be a finite number",
        ),
        (
            MINIMAL + "alignment: {window: [0, " + "9" * 400 + "]}\n",
            ":4: alignment.window[1]: must be a finite number",
        ),
        (
            MINIMAL + "weights: {mae: " + "9" * 400 + "}\n",
            ":4: weights.mae: must be a finite number",
        ),
        (
            MINIMAL.replace("reference: a.csv", 'reference: "a\\0.csv"'),
            ":1: reference.path: a file path cannot contain a NUL character",
        ),
        (
            MINIMAL.replace("model: b.csv", 'model: {fmu: "m\\0.fmu"}'),
            ":2: model.fmu: a file path cannot contain a NUL character",
        ),
        (MINIMAL + "min_phi: .nan\n", ":4: min_phi: must be a finite number"),
        ("\ufeff" + MINIMAL, None),
        ("sets: [{signal: .inf}]\nreference: a.csv\nmodel: b.csv\n", None),
    ],
    ids=lambda value: None if value is None else str(value)[:24],
)
def test_adversarial_specs(text: str, expected: str | None) -> None:
    if expected is None:
        assert parse_spec_text(text, SPEC_PATH).sets
        return
    with pytest.raises(SpecError) as caught:
        parse_spec_text(text, SPEC_PATH)
    assert str(caught.value).startswith(str(SPEC_PATH))
    assert expected in str(caught.value)


def test_symlink_loop_in_a_data_path_is_a_spec_error(tmp_path: Path) -> None:
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    spec = tmp_path / "loop.hevval.yaml"
    with pytest.raises(SpecError, match=r"loop\.hevval\.yaml:1: reference\.path: cannot resolve"):
        parse_spec_text(MINIMAL.replace("a.csv", "loop1/a.csv"), spec)


# --------------------------------------------------------------------------------------------
# Expression evaluator

COLUMN_SOURCES = {"a": "a", "`b [x]`": "b [x]", "c.d": "c.d", "`é ☃`": "é ☃"}
CONSTANTS = st.one_of(
    st.integers(-10, 10).map(str),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.sampled_from(["1e308", "1e-320", "0", "-0.0", "2**1024", "10**400", "1e400", "9" * 400]),
)
LEAVES = st.one_of(st.sampled_from(sorted(COLUMN_SOURCES)), CONSTANTS)


def _extend(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    def call(name: str) -> st.SearchStrategy[str]:
        arity = len(FUNCTIONS[name].params)
        return st.lists(inner, min_size=arity, max_size=arity).map(
            lambda args: f"{name}({', '.join(args)})"
        )

    operators = ["+", "-", "*", "/", "**", "<", "<=", ">", ">=", "==", "!="]
    return st.one_of(
        st.tuples(inner, st.sampled_from(operators), inner).map(
            lambda t: f"({t[0]} {t[1]} {t[2]})"
        ),
        inner.map(lambda x: f"-{x}"),
        st.sampled_from(sorted(FUNCTIONS)).flatmap(call),
        st.tuples(st.sampled_from(["lag", "smooth"]), inner, CONSTANTS).map(
            lambda t: f"{t[0]}({t[1]}, {t[2]})"
        ),
    )


EXPRESSIONS = st.recursive(LEAVES, _extend, max_leaves=10)
EDGE_FLOATS = st.one_of(
    st.floats(),
    st.sampled_from([1e300, -1e300, 1e-300, 5e-324, 0.0, -0.0, np.nan, np.inf, -np.inf]),
)


@st.composite
def columns_and_time(draw: st.DrawFn) -> tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]:
    n = draw(st.integers(0, 8))
    kind = draw(st.sampled_from(["increasing", "increasing", "random", "repeated", "nan"]))
    if kind == "increasing":
        steps = draw(hnp.arrays(np.float64, n, elements=st.floats(1e-3, 10.0)))
        time = np.cumsum(steps)
    elif kind == "random":
        time = draw(hnp.arrays(np.float64, n, elements=EDGE_FLOATS))
    elif kind == "repeated":
        time = np.zeros(n)
    else:
        time = np.full(n, np.nan)
    columns: dict[str, npt.NDArray[Any]] = {}
    for name in COLUMN_SOURCES.values():
        shape = draw(
            st.sampled_from(["f64", "f64", "f32", "int", "bool", "short", "2d", "text", "-"])
        )
        if shape == "f64":
            columns[name] = draw(hnp.arrays(np.float64, n, elements=EDGE_FLOATS))
        elif shape == "f32":
            columns[name] = draw(hnp.arrays(np.float32, n, elements=st.floats(width=32)))
        elif shape == "int":
            columns[name] = np.arange(n, dtype=np.int64) * 10**17
        elif shape == "bool":
            columns[name] = np.ones(n, dtype=bool)
        elif shape == "short":
            columns[name] = np.ones(max(n - 1, 0))
        elif shape == "2d":
            columns[name] = np.ones((n, 2))
        elif shape == "text":
            columns[name] = np.array(["x"] * n, dtype=object)
    return time, columns


@given(EXPRESSIONS, columns_and_time())
@budget(300)
def test_expressions_on_degenerate_columns(
    source: str, case: tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]
) -> None:
    time, columns = case
    try:
        expression = parse_signal(source)
        result = expression.evaluate(columns, time)
    except ExpressionError as exc:
        error = exc
    else:
        _note("result")
        assert result.dtype == np.float64
        assert result.shape == time.shape
        return
    _note("ExpressionError")
    assert error.problem
    if error.problem.startswith(("unknown column", "column ")):
        assert any(repr(name) in error.problem for name in COLUMN_SOURCES.values())


@given(EXPRESSIONS)
@budget(150)
def test_expressions_inside_a_spec_name_file_line_and_key(source: str) -> None:
    document = {"reference": "a.csv", "model": "b.csv", "sets": [{"signal": "x", "ref": source}]}
    try:
        parse_spec_text(yaml.safe_dump(document, width=10_000), SPEC_PATH)
    except SpecError as exc:
        error = exc
    else:
        return
    assert str(error).startswith(f"{SPEC_PATH}:4: sets[0].ref: "), str(error)


# --------------------------------------------------------------------------------------------
# Data files


def _check_record(record: Record, path: str) -> None:
    assert record.source == path
    for channel in record.channels.values():
        assert channel.time.dtype == np.float64
        assert np.all(np.isfinite(channel.time))
        assert np.all(np.diff(channel.time) > 0)
        assert channel.values.shape == channel.time.shape


def _data_outcome(
    path: str, columns: list[str] | None, options: SourceOptions, *, collect: bool = False
) -> None:
    message: str | None = None
    column: str | None = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            record = read_record(path, columns, options)
        except DataError as exc:
            # Only text leaves the block, so whatever the exception's traceback kept alive (a
            # reader's open file) is released, and warns, inside it.
            message, column = str(exc), exc.column
        else:
            _note("record")
            _check_record(record, path)
            del record
        if collect:
            gc.collect()
    if message is not None:
        _note("DataError")
        assert message.startswith(path), message
        if column is not None:
            assert repr(column) in message
    # A reader that leaks a file handle or warns would fail a user's warnings-as-errors run.
    assert [str(w.message) for w in caught] == []


CELLS = st.one_of(
    st.floats(-1e3, 1e3).map(repr),
    st.floats().map(repr),
    st.integers().map(str),
    st.text(max_size=6),
    st.sampled_from(["", "nan", "inf", "1,5", "1e400", "-0", "TRUE", "1.0.0", '"', '"a,b"', "\r"]),
)
HEADERS = ["time", "t", "v", "w [A]", "v", "", "é", "Zeit", "x"]


@st.composite
def delimited_files(draw: st.DrawFn) -> bytes:
    if draw(st.integers(0, 7)) == 0:
        data: bytes = draw(st.binary(max_size=300))
        return data
    sep = draw(st.sampled_from([",", ";", "\t", "|"]))
    n_columns = draw(st.integers(1, 4))
    header = draw(st.lists(st.sampled_from(HEADERS), min_size=n_columns, max_size=n_columns))
    increasing = draw(st.booleans())
    # Mostly numeric tables reach the time checks and the record; the rest test the parser.
    cells_of = st.floats(-1e3, 1e3).map(repr) if draw(st.booleans()) else CELLS
    rows = []
    for index in range(draw(st.integers(0, 6))):
        cells = [draw(cells_of) for _ in range(n_columns)]
        if increasing:
            cells[0] = str(index * 0.1)
        if draw(st.integers(0, 9)) == 0:
            cells = cells[: draw(st.integers(0, n_columns + 1))]
        rows.append(sep.join(cells))
    text = "\n".join([sep.join(header), *rows]) + draw(st.sampled_from(["", "\n", "\r\n"]))
    encoding = draw(st.sampled_from(["utf-8", "latin-1", "utf-16", "cp1252", "utf-8-sig"]))
    encoded = text.encode(encoding, errors="replace")
    if draw(st.booleans()):
        encoded = encoded[: draw(st.integers(0, len(encoded)))]
    return encoded


@given(
    delimited_files(),
    st.sampled_from([None] * 20 + [",", ";", "\t", " ", "::", "\\s+", "(", "ab", "\x00", "["]),
    st.sampled_from([None] * 20 + ["utf-8", "latin-1", "utf-16", "nope", "rot13", "hex", "idna"]),
    st.sampled_from([None] * 10 + [".", ",", "", "ab", ";"]),
    st.sampled_from([None, None, None, ["v"], ["w [A]", "v"], ["nope"], []]),
    st.sampled_from([None] * 6 + ["t", "time", "zz", ""]),
    st.sampled_from([".csv", ".tsv", ".txt"]),
)
@budget(200)
def test_delimited_text(
    tmp_path_factory: pytest.TempPathFactory,
    data: bytes,
    sep: str | None,
    encoding: str | None,
    decimal: str | None,
    columns: list[str] | None,
    time: str | None,
    extension: str,
) -> None:
    path = tmp_path_factory.getbasetemp() / f"fuzz{extension}"
    path.write_bytes(data)
    options = SourceOptions(sep=sep, encoding=encoding, decimal=decimal, time=time)
    _data_outcome(str(path), columns, options)


SEED_NAMES = [
    "seed.parquet",
    "seed.mat",
    "seedz.mat",
    "seed.h5",
    "seed73.mat",
    "seed.mf4",
    "seed.mdf",
]


def _seed_files(folder: Path) -> dict[str, bytes]:
    """One small valid file per binary format, each written by that format's own library."""
    import h5py
    import scipy.io
    from asammdf import MDF, Signal

    t = np.arange(0.0, 2.0, 0.1)
    v = np.sin(t)
    frame = pd.DataFrame({"time": t, "v": v, "w [A]": (2 * v).astype(np.float32)})
    frame.to_parquet(folder / "seed.parquet")
    scipy.io.savemat(folder / "seed.mat", {"time": t, "v": v, "s": {"time": t, "v": v}})
    scipy.io.savemat(folder / "seedz.mat", {"time": t, "v": v}, do_compression=True)
    with h5py.File(folder / "seed.h5", "w") as handle:
        handle["time"] = t
        handle["v"] = v
        handle["g/time"] = t
        handle["g/v"] = v
    with h5py.File(folder / "seed73.mat", "w", userblock_size=512) as handle:
        handle["time"] = t
        handle["v"] = v
    mdf = MDF(version="4.10")
    mdf.append([Signal(v, t, name="v", unit="A"), Signal(2 * v, t, name="w [A]")])
    mdf.save(folder / "seed.mf4", overwrite=True)
    mdf.close()
    mdf3 = MDF(version="3.30")
    mdf3.append([Signal(v, t, name="v")])
    mdf3.save(folder / "seed.mdf", overwrite=True)
    mdf3.close()
    return {name: (folder / name).read_bytes() for name in SEED_NAMES}


class Seeds(dict[str, bytes]):
    """The seed files by name; Hypothesis prints fixtures with a failing example, so briefly."""

    def __repr__(self) -> str:
        return f"<seed files {', '.join(self)}>"


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> Seeds:
    return Seeds(_seed_files(tmp_path_factory.mktemp("seeds")))


# One damage: (operation, position, byte, inserted bytes). Drawn in a fixed shape, apart from
# the seed, so that an example replays the same way whatever the seed file looks like (seeds
# carry creation times, so their length can change between sessions).
DAMAGE = st.tuples(
    st.sampled_from(["truncate", "flip", "byte", "insert", "zero"]),
    st.integers(0, 2**32 - 1),
    st.integers(0, 255),
    st.binary(min_size=1, max_size=8),
)


def damage(seed: bytes, damages: list[tuple[str, int, int, bytes]]) -> bytes:
    data = bytearray(seed)
    for operation, where, value, inserted in damages:
        if not data:
            break
        index = where % len(data)
        if operation == "truncate":
            data = data[:index]
        elif operation == "flip":
            data[index] ^= 1 << (value % 8)
        elif operation == "byte":
            data[index] = value
        elif operation == "insert":
            data[index:index] = inserted
        else:
            data[index : index + 64] = bytes(len(data[index : index + 64]))
    return bytes(data)


@pytest.mark.parametrize("seed_name", SEED_NAMES)
@given(
    damages=st.lists(DAMAGE, max_size=3),
    columns=st.sampled_from([None, ["v"], ["v", "nope"], ["w [A]"]]),
    group=st.sampled_from([None, None, "g", "s", "x"]),
)
@budget(50)
def test_damaged_binary_files(
    tmp_path_factory: pytest.TempPathFactory,
    seeds: Seeds,
    seed_name: str,
    damages: list[tuple[str, int, int, bytes]],
    columns: list[str] | None,
    group: str | None,
) -> None:
    suffix = Path(seed_name).suffix
    path = tmp_path_factory.getbasetemp() / f"damaged{suffix}"
    path.write_bytes(damage(seeds[seed_name], damages))
    has_groups = suffix in (".mat", ".h5")
    _data_outcome(str(path), columns, SourceOptions(group=group if has_groups else None))


@pytest.mark.parametrize("value", [0x00, 0xFF])
def test_every_damaged_hdf5_header_byte(tmp_path: Path, seeds: Seeds, value: int) -> None:
    # Some superblock damage lets the file open and fails only when its groups are walked
    # (RuntimeError "Object visitation failed" from the HDF5 library).
    for index in range(256):
        content = bytearray(seeds["seed.h5"])
        content[index] = value
        path = tmp_path / f"h{index}.h5"
        path.write_bytes(bytes(content))
        for group in (None, "g"):
            _data_outcome(str(path), None, SourceOptions(group=group))


@pytest.mark.parametrize("index", [8, 9, 10, 11])
def test_mdf_with_a_non_ascii_version_leaks_no_file(
    tmp_path: Path, seeds: Seeds, index: int
) -> None:
    # asammdf leaves the file open when the version field does not decode; the reader closes it.
    content = bytearray(seeds["seed.mf4"])
    content[index] = 0xFF
    path = tmp_path / "version.mf4"
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="cannot read this MDF file"):
        read_record(str(path), None, SourceOptions())
    _data_outcome(str(path), None, SourceOptions(), collect=True)


@pytest.mark.parametrize("encoding", ["nope", "hex", "rot13", "base64", "idna"])
def test_unusable_encoding_is_a_data_error(tmp_path: Path, encoding: str) -> None:
    path = tmp_path / "a.csv"
    path.write_text("t,v\n0,1\n1,2\n")
    with pytest.raises(DataError) as caught:
        read_record(str(path), None, SourceOptions(encoding=encoding))
    assert str(caught.value).startswith(f"{path}: encoding: {encoding!r} is not a text encoding")


@pytest.mark.parametrize("kind", [0, 8, 10, 11, 19, 200])
def test_mat_element_of_undefined_type_is_refused(tmp_path: Path, seeds: Seeds, kind: int) -> None:
    # scipy.io.loadmat crashes the process (SIGSEGV) on such an element instead of raising.
    content = bytearray(seeds["seed.mat"])
    real_part = content.index(struct.pack("<II", 9, 160))  # 20 doubles of the first vector
    struct.pack_into("<I", content, real_part, kind)
    path = tmp_path / "bad.mat"
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=f"undefined data type {kind} at byte {real_part}"):
        read_record(str(path), None, SourceOptions())


def _mdf_seed_and_address(
    seeds: Seeds, name: str, locate: Callable[[Any], Any]
) -> tuple[bytearray, int]:
    """A copy of an MDF seed to damage, and the address of the block ``locate`` picks in it."""
    from asammdf import MDF

    content = bytearray(seeds[name])
    with MDF(io.BytesIO(bytes(content))) as mdf:
        address = int(locate(mdf).address)
    return content, address


@pytest.mark.parametrize(("name", "field"), [("seed.mdf", 20), ("seed.mf4", 96)])
def test_mdf_channel_past_the_end_of_its_record_is_refused(
    tmp_path: Path, seeds: Seeds, name: str, field: int
) -> None:
    # asammdf copies channel bytes out of each record in C without bounds checks; a record
    # size smaller than a channel's end overruns the heap (seen as SIGABRT/SIGSEGV).
    content, address = _mdf_seed_and_address(seeds, name, lambda mdf: mdf.groups[0].channel_group)
    path = tmp_path / name
    # The record size field of the channel group block (MDF 3: uint16, MDF 4: uint32).
    struct.pack_into("<H" if name.endswith(".mdf") else "<I", content, address + field, 2)
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=r"channel 'time' ends at byte 8 of a 2-byte record"):
        read_record(str(path), None, SourceOptions())


def test_hdf5_names_that_are_not_utf8(tmp_path: Path) -> None:
    # h5py returns such link names as bytes; a damaged name byte produces one.
    import h5py

    path = tmp_path / "names.h5"
    t = np.arange(5.0)
    with h5py.File(path, "w") as handle:
        handle["time"] = t
        handle[b"v\xff"] = 2 * t
        handle[b"g\xfe/time"] = t
    record = read_record(str(path), None, SourceOptions())
    assert list(record.channels) == ["v\ufffd"]
    with pytest.raises(DataError, match="no group 'x' in this file; set `group:` to one of: 'g"):
        read_record(str(path), None, SourceOptions(group="x"))


CRASH_HUNT = int(os.environ.get("HEVVAL_CRASH_HUNT", "0") or 0)
# Another seed damages the files in other places.
CRASH_SEED = os.environ.get("HEVVAL_CRASH_SEED", "20240501")

HUNTER = """
import json, random, re, resource, signal, sys, warnings
from pathlib import Path
from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import SourceOptions
from pytest_hevval.errors import DataError

# A damaged size field can make a reader allocate tens of gigabytes; with the address space
# capped, such an allocation fails here instead of the machine running out of memory.
resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))


class Hang(BaseException):  # not an Exception: readers that catch those must not hide it
    pass


def hang(signum, frame):
    raise Hang()


# A read that loops forever is a defect too: no file here takes a second to read.
signal.signal(signal.SIGALRM, hang)
UNITS = {"KiB": 1 << 10, "MiB": 1 << 20, "GiB": 1 << 30, "TiB": 1 << 40, "PiB": 1 << 50}
warnings.simplefilter("ignore")
folder, count, seed = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
rng = random.Random(seed)
tally = {}
for source in sorted(folder.glob("seed*")):
    original = source.read_bytes()
    current = folder / ("current" + source.suffix)
    for _ in range(count):
        data = bytearray(original)
        for _ in range(rng.randint(0, 3)):
            if not data:
                break
            index = rng.randrange(len(data))
            operation = rng.choice("tfbiz")
            if operation == "t":
                data = data[:index]
            elif operation == "f":
                data[index] ^= 1 << rng.randrange(8)
            elif operation == "b":
                data[index] = rng.randrange(256)
            elif operation == "i":
                data[index:index] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
            else:
                data[index : index + 64] = bytes(len(data[index : index + 64]))
        # Written before reading: after a crash it is the input that caused it.
        current.write_bytes(bytes(data))
        groups = [None, None, "g", "s", "x"] if source.suffix in (".mat", ".h5") else [None]
        group = rng.choice(groups)
        columns = rng.choice([None, ["v"], ["v", "nope"], ["w [A]"]])
        try:
            signal.alarm(10)
            try:
                read_record(str(current), columns, SourceOptions(group=group))
            finally:
                signal.alarm(0)
            outcome = "record"
        except DataError as exc:
            outcome = "DataError"
            wanted = re.search(r"Unable to allocate ([0-9.]+) (KiB|MiB|GiB|TiB|PiB)", str(exc))
            # Beyond any machine's memory the request fails at once, which is harmless; a
            # request a machine could grant is the memory exhaustion this looks for.
            if wanted and 1 << 30 < float(wanted[1]) * UNITS[wanted[2]] < 1 << 40:
                outcome = "allocation of " + wanted[0][len("Unable to allocate ") :]
                current.rename(folder / f"allocation-{rng.random()}{source.suffix}")
        except (Exception, Hang) as exc:
            outcome = type(exc).__name__
            current.rename(folder / f"{type(exc).__name__}-{rng.random()}{source.suffix}")
        current.unlink(missing_ok=True)
        key = source.name + " " + outcome
        tally[key] = tally.get(key, 0) + 1
print(json.dumps(tally))
"""


@pytest.mark.skipif(
    not CRASH_HUNT, reason="set HEVVAL_CRASH_HUNT=N to read N damaged files per format"
)
def test_damaged_binary_files_never_crash_the_process(tmp_path: Path) -> None:
    # The binary readers are C extensions: a defect there kills the process, which a
    # Hypothesis target cannot report. A child process reads the damaged files instead.
    _seed_files(tmp_path)
    # glibc's and Python's checking allocators stop at a heap overrun instead of crashing
    # somewhere later, or not at all.
    env = {**os.environ, "MALLOC_CHECK_": "3", "PYTHONMALLOC": "malloc_debug"}
    try:
        completed = subprocess.run(
            [sys.executable, "-c", HUNTER, str(tmp_path), str(CRASH_HUNT), CRASH_SEED],
            capture_output=True,
            text=True,
            check=False,
            env=env,
            # A hang inside C code, where the child's own alarm cannot interrupt it.
            timeout=300 + CRASH_HUNT * len(SEED_NAMES) * 0.1,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"reader hung on {sorted(tmp_path.glob('current.*'))}")
    crashed = sorted(tmp_path.glob("current.*"))
    assert completed.returncode == 0, f"reader crashed ({completed.returncode}) on {crashed}"
    tally = json.loads(completed.stdout.strip().splitlines()[-1])
    # The per-format outcomes are the figures docs/reliability.md records (shown with -s).
    print("damaged files read, by seed and outcome:", json.dumps(tally, sort_keys=True))
    assert {key.split(" ")[1] for key in tally} <= {"record", "DataError"}, tally
    assert sum(tally.values()) == CRASH_HUNT * len(SEED_NAMES)


def test_mat_array_flagged_complex_without_imaginary_part_is_refused(
    tmp_path: Path, seeds: Seeds
) -> None:
    # scipy.io.loadmat then reads the next variable's tag as the imaginary part: SIGSEGV.
    content = bytearray(seeds["seed.mat"])
    flags = content.index(struct.pack("<II", 6, 8), 128) + 8  # array flags of the first array
    content[flags + 1] |= 0x08  # the complex bit, 0x800 of the flags word
    path = tmp_path / "complex.mat"
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="the array at byte 128 ends before all its parts"):
        read_record(str(path), None, SourceOptions())


def test_mat_warning_about_corrupt_data_is_an_error(tmp_path: Path) -> None:
    # A MAT v4 header claiming VAX byte order makes scipy warn "returned data may be corrupt"
    # and carry on; that data must not be scored, and under -W error the warning would escape.
    path = tmp_path / "vax.mat"
    path.write_bytes(b"\x00\x08" + bytes(18))
    with pytest.raises(DataError, match="returned data may be corrupt"):
        read_record(str(path), None, SourceOptions())
    _data_outcome(str(path), None, SourceOptions())


def test_mdf_record_larger_than_its_data_is_refused(tmp_path: Path, seeds: Seeds) -> None:
    # A damaged invalidation-byte count (one byte of the channel group block) once made
    # asammdf allocate gigabytes for a 2 kB file, until the process was killed.
    content, address = _mdf_seed_and_address(
        seeds, "seed.mf4", lambda mdf: mdf.groups[0].channel_group
    )
    path = tmp_path / "seed.mf4"
    struct.pack_into("<I", content, address + 100, 0xD8000000)  # cg_inval_bytes
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=r"a record of \d+ bytes is larger than the 480 bytes"):
        read_record(str(path), None, SourceOptions())


def test_mdf_records_beyond_the_stored_data_are_refused(tmp_path: Path, seeds: Seeds) -> None:
    # A damaged record count made asammdf allocate 7.9 GB per channel for a 2 kB file.
    content, address = _mdf_seed_and_address(
        seeds, "seed.mf4", lambda mdf: mdf.groups[0].channel_group
    )
    path = tmp_path / "seed.mf4"
    struct.pack_into("<Q", content, address + 80, 1_056_964_628)  # cg_cycle_count
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="1056964628 records of 24 bytes need 25367151072 bytes"):
        read_record(str(path), None, SourceOptions())


def test_mdf3_record_count_beyond_the_file_is_refused(tmp_path: Path, seeds: Seeds) -> None:
    # MDF 3 stores no block sizes; asammdf derives them from the record count, so a damaged
    # count asked for 13.9 GiB for a 1.6 kB file (found by the crash hunt).
    content, address = _mdf_seed_and_address(
        seeds, "seed.mdf", lambda mdf: mdf.groups[0].channel_group
    )
    path = tmp_path / "seed.mdf"
    struct.pack_into("<I", content, address + 22, 1_865_263_528)  # cg number of records
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=r"a data block ends at byte \d+, past the end of the"):
        read_record(str(path), None, SourceOptions())


@pytest.mark.parametrize(("seed", "link"), [("seed.mf4", ("<Q", 24)), ("seed.mdf", ("<I", 4))])
def test_mdf_block_list_that_loops_is_refused(
    tmp_path: Path, seeds: Seeds, seed: str, link: tuple[str, int]
) -> None:
    # A channel whose "next" link points back at itself made asammdf's opening loop forever
    # (found by the crash hunt, in MDF 4 and MDF 3 files).
    content, channel = _mdf_seed_and_address(seeds, seed, lambda mdf: mdf.groups[0].channels[-1])
    path = tmp_path / seed
    code, offset = link
    struct.pack_into(code, content, channel + offset, channel)  # next channel → itself
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=rf"the block at byte {channel} is linked to twice"):
        read_record(str(path), None, SourceOptions())


def test_mat_small_element_claiming_more_than_four_bytes_is_refused(
    tmp_path: Path, seeds: Seeds
) -> None:
    # A small-format tag (size in its upper half) claiming 128 bytes: scipy.io.loadmat copies
    # them out of the 4-byte slot and segfaults (found by the crash hunt, seed 4).
    content = bytearray(seeds["seed.mat"])
    flags_tag = content.index(struct.pack("<II", 6, 8), 128)  # array flags of the first array
    struct.pack_into("<I", content, flags_tag, (128 << 16) | 6)
    path = tmp_path / "small.mat"
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match=rf"small data element at byte {flags_tag} claims more"):
        read_record(str(path), None, SourceOptions())


def test_mat_struct_array_larger_than_its_bytes_is_refused(tmp_path: Path) -> None:
    # One damaged dimension of a struct array made scipy.io.loadmat allocate an object array of
    # 2^30 elements (8 GB) for a 1 kB file (found by the crash hunt, seed 4).
    import scipy.io

    path = tmp_path / "log.mat"
    scipy.io.savemat(path, {"s": {"time": np.arange(3.0), "v": np.ones(3)}})
    content = bytearray(path.read_bytes())
    # The struct's dimensions [1, 1] are the first int32 pair tagged (5, 8) after its flags.
    dims = content.index(struct.pack("<IIii", 5, 8, 1, 1), 128)
    struct.pack_into("<i", content, dims + 12, 0x40000001)
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="claims 1073741825 elements"):
        read_record(str(path), None, SourceOptions(group="s"))


def test_mdf3_that_fails_to_open_leaks_no_file(tmp_path: Path, seeds: Seeds) -> None:
    # A damaged record-ID count in an MDF 3 data group: asammdf's constructor fails with
    # KeyError 0 after opening the file, and left it open (found by the large fuzz run).
    content, data_group = _mdf_seed_and_address(
        seeds, "seed.mdf", lambda mdf: mdf.groups[0].data_group
    )
    struct.pack_into("<H", content, data_group + 22, 137)  # number of record IDs
    path = tmp_path / "ids.mdf"
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="the reader said: KeyError: 0"):
        read_record(str(path), None, SourceOptions())
    _data_outcome(str(path), None, SourceOptions(), collect=True)


def _loop_every_name_heap(content: bytearray) -> int:
    """Make the free-space list of every local heap point back at itself; return how many."""
    looped = 0
    base = content.find(b"\x89HDF\r\n\x1a\n")  # addresses count from the superblock
    start = content.find(b"HEAP")
    while start >= 0:
        _, free, data = struct.unpack_from("<QQQ", content, start + 8)
        if free != 1:  # 1 ends the list
            struct.pack_into("<Q", content, base + data + free, free)
            looped += 1
        start = content.find(b"HEAP", start + 4)
    return looped


@pytest.mark.parametrize(("seed", "group"), [("seed.h5", "g"), ("seed73.mat", None)])
def test_hdf5_name_heap_that_loops_is_refused(
    tmp_path: Path, seeds: Seeds, seed: str, group: str | None
) -> None:
    # A free-space list that points back at itself made libhdf5 loop forever while listing
    # the group, where no signal reaches Python (found by the crash hunt, seed 2).
    content = bytearray(seeds[seed])
    assert _loop_every_name_heap(content) >= 1
    path = tmp_path / seed
    path.write_bytes(bytes(content))
    with pytest.raises(DataError, match="lists free space a second time"):
        read_record(str(path), None, SourceOptions(group=group))
