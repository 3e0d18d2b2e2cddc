"""Where and when the model is wrong, from a spec: ``local:`` and ``regions:`` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_hevval import cli
from pytest_hevval.core.groups import (
    Grouping,
    SumTable,
    grouped_tables,
    labelled_table,
    segment_sums,
)
from pytest_hevval.errors import SpecError
from pytest_hevval.results.recorded import RecordedSpec
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import load_spec, parse_spec_text
from tests.conftest import needs_kernel
from tests.recorded_runs import recorded
from tests.strategies import signal_pairs

pytest_plugins = ["pytester"]

RATE_HZ = 10.0
DURATION_S = 1800.0
# The injected error: a 60 s stretch, and every sample above 100 km/h.
STRETCH_S = (1200.0, 1260.0)
FAST_KMH = 100.0


def write_trip(folder: Path, *, stretch: bool, fast: bool) -> None:
    """A half-hour 10 Hz trip whose model is exact except where an error is injected."""
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
    rng = np.random.default_rng(1)
    # Speed sweeps 0–138 km/h several times; power follows speed and acceleration.
    speed = 69.0 - 69.0 * np.cos(2 * np.pi * t / 300.0) + rng.normal(0, 0.05, t.size)
    speed = np.clip(speed, 0.0, 138.0)
    power = 0.4 * speed + 5.0 * np.sin(2 * np.pi * t / 37.0) + rng.normal(0, 0.3, t.size)
    modelled = power.copy()
    if stretch:
        inside = (t >= STRETCH_S[0]) & (t < STRETCH_S[1])
        modelled[inside] += 8.0
    if fast:
        modelled[speed > FAST_KMH] += 8.0
    lines = ["time,speed,power,heater"]
    heater = (t < 300.0).astype(float)
    lines += [
        f"{a:.1f},{b:.6f},{c:.6f},{h:g}" for a, b, c, h in zip(t, speed, power, heater, strict=True)
    ]
    (folder / "measured.csv").write_text("\n".join(lines) + "\n")
    lines = ["time,power"] + [f"{a:.1f},{c:.6f}" for a, c in zip(t, modelled, strict=True)]
    (folder / "model.csv").write_text("\n".join(lines) + "\n")


SPEC = """\
name: localised
reference: {path: measured.csv, time: time}
model: {path: model.csv, time: time}
local:
  window_s: 30
  phases: speed
  conditions:
    heater_on: {when: "heater > 0.5", thresholds: {mae: 0.5}}
  gate: {thresholds: {mae: 0.97}}
regions:
  by: [speed]
  bins: [[0, 20, 40, 60, 80, 100, 120, 140, 160]]
  min_samples: 50
  gate: {thresholds: {mae: 0.97}}
sets:
  - {signal: P, ref: power, sim: power, unit: kW}
"""


def _evaluate(folder: Path, spec_text: str = SPEC) -> object:
    path = folder / "trip.hevval.yaml"
    path.write_text(spec_text)
    return evaluate_spec(load_spec(path), rootdir=folder)


def test_an_error_in_one_stretch_is_found_in_exactly_that_stretch(tmp_path: Path) -> None:
    write_trip(tmp_path, stretch=True, fast=False)
    evaluation = _evaluate(tmp_path)
    (signal,) = evaluation.result.signals  # type: ignore[attr-defined]
    assert signal.failures == []  # the record as a whole passes: the error averages out
    (window_miss,) = [f for f in signal.local_failures if f.scope == "windows"]
    assert window_miss.characteristic == "mae"
    assert set(window_miss.where) == {"1200–1230 s", "1230–1260 s"}
    assert signal.local.concentration["spans_s"] == [[1200.0, 1260.0]]
    assert "in 2 windows: 1200–1260 s" in signal.local.concentration["sentence"]
    assert not signal.passed


def test_an_error_above_100_kmh_fails_exactly_those_cells(tmp_path: Path) -> None:
    write_trip(tmp_path, stretch=False, fast=True)
    evaluation = _evaluate(tmp_path)
    (signal,) = evaluation.result.signals  # type: ignore[attr-defined]
    (cell_miss,) = [f for f in signal.local_failures if f.scope == "regions"]
    assert set(cell_miss.where) == {"speed 100–120", "speed 120–140"}
    grid = evaluation.result.local.regions  # type: ignore[attr-defined]
    assert grid.unvisited == ((7,),)  # 140–160 km/h is declared but never driven
    assert grid.phi[7] is None
    mae = dict(zip(grid.labels, signal.local.regions.lambdas["mae"], strict=True))
    assert all(mae[label] > 0.99 for label in grid.labels[:5])


def test_a_condition_loosens_the_windows_where_it_holds(tmp_path: Path) -> None:
    write_trip(tmp_path, stretch=False, fast=False)
    # Inject the error where the heater runs (the first 300 s): the condition's looser MAE
    # threshold applies there, so the window gate passes; without it, it fails there.
    measured = (tmp_path / "measured.csv").read_text().splitlines()
    model_lines = (tmp_path / "model.csv").read_text().splitlines()
    out = [model_lines[0]]
    for row in model_lines[1:]:
        t, p = row.split(",")
        out.append(f"{t},{float(p) + (8.0 if float(t) < 300 else 0.0):.6f}")
    (tmp_path / "model.csv").write_text("\n".join(out) + "\n")
    assert measured
    loose = _evaluate(tmp_path)
    assert [f.scope for f in loose.result.signals[0].local_failures] == []  # type: ignore[attr-defined]
    strict = _evaluate(tmp_path, SPEC.replace("thresholds: {mae: 0.5}", "thresholds: {}"))
    (miss,) = strict.result.signals[0].local_failures  # type: ignore[attr-defined]
    assert miss.scope == "windows"
    assert len(miss.where) == 10  # the ten 30 s windows of the first 300 s


def test_share_lets_a_few_windows_miss(tmp_path: Path) -> None:
    write_trip(tmp_path, stretch=True, fast=False)
    spec = SPEC.replace(
        "gate: {thresholds: {mae: 0.97}}\nregions",
        "gate: {thresholds: {mae: 0.97}, share: 0.95}\nregions",
    )
    evaluation = _evaluate(tmp_path, spec)
    assert evaluation.result.signals[0].local_failures == []  # type: ignore[attr-defined]


def test_phases_and_conditions_are_tabled(tmp_path: Path) -> None:
    write_trip(tmp_path, stretch=False, fast=False)
    (signal,) = _evaluate(tmp_path).result.signals  # type: ignore[attr-defined]
    assert signal.local.phases.labels == ("stop", "accelerate", "cruise", "brake")
    assert sum(signal.local.phases.n) == signal.n_samples
    heater = signal.local.conditions["heater_on"]
    assert heater.n[0] == 3000  # 300 s at 10 Hz
    assert heater.n[0] + heater.n[1] == signal.n_samples


def test_the_json_result_round_trips(tmp_path: Path) -> None:
    from pytest_hevval.results.spec_result import SpecResult

    write_trip(tmp_path, stretch=True, fast=True)
    result = _evaluate(tmp_path).result  # type: ignore[attr-defined]
    data = json.loads(json.dumps(result.to_dict()))
    again = SpecResult.from_dict(data)
    assert again.to_dict() == data
    assert not again.signals[0].passed
    # The tables read back equal the scored ones, NaN (a cell too small to judge) included.
    scored, read = result.signals[0].local, again.signals[0].local
    assert np.isnan(scored.regions.lambdas["mae"]).any()
    assert read == scored
    assert read.regions != scored.windows
    assert not read.regions.rms.flags.writeable


def test_a_table_cannot_be_changed_by_its_reader(tmp_path: Path) -> None:
    """The tables of a spec's signals share the arrays they were computed in: a column is
    read-only, so a reader changing one would fail rather than change every other table."""
    write_trip(tmp_path, stretch=True, fast=True)
    local = _evaluate(tmp_path).result.signals[0].local  # type: ignore[attr-defined]
    for table in (local.windows, local.phases, local.regions):
        for column in (table.n, table.rms, table.error_share, *table.lambdas.values()):
            with pytest.raises(ValueError, match="read-only"):
                column[0] = 0


def test_building_the_tables_leaves_the_callers_sums_writable() -> None:
    from pytest_hevval.core.groups import Sums
    from pytest_hevval.results.local_tables import GroupTable

    table = np.zeros((2, 10))
    table[:, 0] = [40, 50]
    sums = Sums.of_table(table, 0.0)
    (built,) = GroupTable.many([["a", "b"]], sums, 1.0, "xcorr", 1.0)
    assert not built.n.flags.writeable
    sums.n[0] = 41  # still the caller's to change
    assert built.n.tolist() == [40, 50]


def test_hevval_run_turns_the_results_into_json_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The JSON file and the publisher share one copy of the results' data, and a run that
    writes neither does not make it (a spec's tables cost seconds to turn into JSON)."""
    from pytest_hevval.results.spec_result import SpecResult

    write_trip(tmp_path, stretch=True, fast=True)
    (tmp_path / "trip.hevval.yaml").write_text(SPEC)
    made = []
    to_dict = SpecResult.to_dict

    def counted(self: SpecResult) -> dict[str, object]:
        made.append(self.spec)
        return to_dict(self)

    monkeypatch.setattr(SpecResult, "to_dict", counted)
    monkeypatch.chdir(tmp_path)
    spec = str(tmp_path / "trip.hevval.yaml")
    assert cli.main(["run", spec, "--no-history", "--quiet"]) == 1
    assert made == []
    out = tmp_path / "out.json"
    assert cli.main(["run", spec, "--json", str(out), "--report", "md", "--quiet"]) == 1
    assert len(made) == 1
    data = json.loads(out.read_text())
    assert data["specs"][0]["signals"][0]["local"]["windows"]["n"][0] == 300
    assert "P" in (tmp_path / ".hevval" / "report" / "report.md").read_text()


@pytest.mark.parametrize("exponent", [600, -600])
def test_windows_and_cells_of_huge_or_tiny_signals_match_ordinary_ones(
    tmp_path: Path, exponent: int
) -> None:
    # Squares of 2^±600 overflow or underflow float64; the sums are taken rescaled.
    write_trip(tmp_path, stretch=True, fast=True)
    factor = 2.0**exponent
    scaled_spec = SPEC.replace(
        "unit: kW}", f"unit: kW, ref_scale: {factor!r}, sim_scale: {factor!r}}}"
    )
    plain = _evaluate(tmp_path).result.signals[0]  # type: ignore[attr-defined]
    scaled = _evaluate(tmp_path, scaled_spec).result.signals[0]  # type: ignore[attr-defined]
    for scope in ("windows", "phases", "regions"):
        before, after = getattr(plain.local, scope), getattr(scaled.local, scope)
        np.testing.assert_array_equal(after.n, before.n)
        for name, values in before.lambdas.items():
            np.testing.assert_allclose(after.lambdas[name], values, rtol=1e-9, err_msg=name)
        np.testing.assert_allclose(after.rms / factor, before.rms, rtol=1e-9)
        np.testing.assert_allclose(after.error_share, before.error_share, rtol=1e-9)
    assert scaled.local.concentration == plain.local.concentration
    assert [f.where for f in scaled.local_failures] == [f.where for f in plain.local_failures]


def test_each_signal_of_a_spec_gets_the_tables_it_gets_alone(tmp_path: Path) -> None:
    """The tables of all signals come from one vectorised call: each signal keeps its own
    shift, power-of-two scale and range, as if it were the spec's only signal."""
    write_trip(tmp_path, stretch=True, fast=True)
    signals = {
        "P": "{signal: P, ref: power, sim: power, unit: kW}",
        "huge": f"{{signal: huge, ref: power, sim: power, ref_scale: {2.0**600!r}, "
        f"sim_scale: {2.0**600!r}}}",
        "thrice": "{signal: thrice, ref: power, sim: power, ref_scale: 3.0, sim_scale: 2.9}",
    }
    head = SPEC.split("sets:")[0]

    def spec_of(names: list[str]) -> str:
        return head + "sets:\n" + "".join(f"  - {signals[name]}\n" for name in names)

    together = _evaluate(tmp_path, spec_of(list(signals))).result.signals  # type: ignore[attr-defined]
    assert len(together) == 3
    for result in together:
        (alone,) = _evaluate(tmp_path, spec_of([result.name])).result.signals  # type: ignore[attr-defined]
        assert result.local.to_dict() == alone.local.to_dict(), result.name
        assert result.local_failures == alone.local_failures
    # The scales did reach the tables: the huge copy's errors are 2^600 times P's.
    by_name = {s.name: s for s in together}
    np.testing.assert_allclose(
        by_name["huge"].local.windows.rms / 2.0**600, by_name["P"].local.windows.rms
    )
    assert not np.array_equal(by_name["thrice"].local.windows.rms, by_name["P"].local.windows.rms)


@pytest.mark.parametrize(
    ("fragment", "key", "problem"),
    [
        ("local: {windows: 30}", "local.windows", "unknown key"),
        ("local: {window_s: -1}", "local.window_s", "greater than 0"),
        ("local: {gate: {share: 0.9}}", "local.gate.thresholds", "is required"),
        (
            "local: {gate: {thresholds: {emergent: 0.9}}}",
            "local.gate.thresholds.emergent",
            "not scored over windows",
        ),
        ("regions: {by: []}", "regions.by", "one or two operating variables"),
        ("regions: {by: [a, b], bins: [3]}", "regions.bins", "one entry per variable"),
        ("regions: {by: [a], bins: [[3, 1]]}", "regions.bins[0]", "must increase"),
        (
            "local: {conditions: {cold: {thresholds: {mae: 0.5}}}}",
            "local.conditions.cold.when",
            "is required",
        ),
    ],
)
def test_bad_local_keys_are_spec_errors(fragment: str, key: str, problem: str) -> None:
    text = "reference: {path: a.csv}\nmodel: {path: b.csv}\n" + fragment + "\nsets: [{signal: x}]\n"
    with pytest.raises(SpecError) as raised:
        parse_spec_text(text, Path("bad.hevval.yaml"))
    assert raised.value.key == key
    assert problem in str(raised.value)
    assert "bad.hevval.yaml:" in str(raised.value)


def test_a_node_overrides_the_local_gate() -> None:
    text = SPEC.replace(
        "{signal: P, ref: power, sim: power, unit: kW}",
        "{signal: P, ref: power, sim: power, local_thresholds: {mae: 0.5}}",
    )
    spec = parse_spec_text(text, Path("x.hevval.yaml"))
    (node,) = spec.sets
    assert spec.local_thresholds_for(node) == {"mae": 0.5}
    assert spec.region_thresholds_for(node) == {"mae": 0.97}


# -- the one-pass sums ---------------------------------------------------------------------


@pytest.mark.parametrize("compiled", [False, pytest.param(True, marks=needs_kernel)])
@given(signal_pairs(min_size=12), st.integers(2, 9), st.integers(1, 5))
@settings(max_examples=80, deadline=None)
def test_one_pass_fine_sums_merge_to_the_window_sums(
    compiled: bool, pair: tuple[np.ndarray, np.ndarray], size: int, cells: int
) -> None:
    ref, sim = pair
    n = ref.shape[0]
    window = np.arange(n) // size
    cell = np.arange(n) % cells
    windows = int(window[-1]) + 1
    grouping = Grouping.of(window * cells + cell, (windows, cells))
    tables = grouped_tables(ref, sim, grouping, compiled=compiled)
    merged = tables.rows(grouping.rows(0)).sums()
    starts = np.arange(windows) * size
    direct = segment_sums(ref, sim, starts, np.minimum(starts + size, n))
    scale = float(np.max(np.abs(np.concatenate([ref, sim])))) + 1.0
    for name in ("n", "error_sum", "abs_error", "sq_error", "ref_sum", "cross", "sign_matches"):
        np.testing.assert_allclose(
            getattr(merged, name), getattr(direct, name), rtol=1e-9, atol=1e-9 * scale**2
        )
    np.testing.assert_allclose(merged.error_m2, direct.error_m2, rtol=1e-6, atol=1e-7 * scale**2)


def test_the_compiled_pass_matches_numpy() -> None:
    pytest.importorskip("numba", reason="the compiled pass needs the fast extra (numba)")
    from pytest_hevval.core import kernel

    if kernel.active_path() != "numba":
        pytest.skip("numba is installed but cannot be loaded with this numpy")
    rng = np.random.default_rng(3)
    n = 20_000
    ref = np.cumsum(rng.normal(size=n))
    sim = ref + rng.normal(0, 0.2, n) + 3.0
    labels = (np.arange(n) // 700) * 4 + rng.integers(0, 4, n)
    labels[::97] = -1
    groups = int(labels.max()) + 1
    fast = labelled_table(ref, sim, labels, groups, compiled=True).sums()
    plain = labelled_table(ref, sim, labels, groups, compiled=False).sums()
    for name in ("n", "error_sum", "abs_error", "sq_error", "error_m2", "ref_sq", "cross"):
        np.testing.assert_allclose(getattr(fast, name), getattr(plain, name), rtol=1e-12)
    assert np.array_equal(fast.sign_matches, plain.sign_matches)


@st.composite
def _labelled_pairs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A pair, labels in runs (with samples in no group) and the number of groups; the values
    may need the power-of-two scale (beyond 2^±400) and may hold a NaN."""
    ref, sim = draw(signal_pairs(min_size=1))
    n = ref.shape[0]
    groups = draw(st.integers(1, 8))
    runs = draw(st.lists(st.tuples(st.integers(-1, groups - 1), st.integers(1, 9)), min_size=1))
    labels = np.repeat([g for g, _ in runs], [k for _, k in runs])
    labels = np.resize(labels, n).astype(np.int64)
    factor = draw(st.sampled_from([1.0, 2.0**450, 2.0**-450, 2.0**-1000]))
    ref, sim = ref * factor, sim * factor
    if draw(st.booleans()):
        where = draw(st.integers(0, n - 1))
        (ref if draw(st.booleans()) else sim)[where] = np.nan
    return ref, sim, labels, groups


def _rounding_bound(
    ref: np.ndarray, sim: np.ndarray, labels: np.ndarray, table: SumTable
) -> np.ndarray:
    """How far two orders of summing each column of ``table`` may differ: each term's magnitude
    summed over its group, times the group's size and a few ulps (the compiled pass adds in
    another order and fuses a product into its sum)."""
    r, s = ref * table.scale, sim * table.scale
    e = r - s
    d = e - table.shift
    terms = (d, d * d, e, r, s, r * r, s * s, r * s)
    keep = labels >= 0
    groups = table.values.shape[0]
    n = np.bincount(labels[keep], minlength=groups).astype(np.float64)
    magnitude = np.column_stack(
        [np.zeros(groups)]
        + [np.bincount(labels[keep], weights=np.abs(t)[keep], minlength=groups) for t in terms]
        + [np.zeros(groups)]
    )
    return 4.0 * np.finfo(np.float64).eps * (n[:, None] + 2.0) * magnitude


@needs_kernel
@given(_labelled_pairs())
@settings(max_examples=150, deadline=None)
def test_the_compiled_pass_agrees_with_numpy_to_rounding(
    case: tuple[np.ndarray, np.ndarray, np.ndarray, int],
) -> None:
    """The compiled pass reassociates its sums (as the main pass does): every column within the
    rounding of a different order, the counts and sign matches exact, and the same shift and
    scale, with the scale found from the pass's own sums of squares (NaN included)."""
    ref, sim, labels, groups = case
    with np.errstate(invalid="ignore", over="ignore"):
        fast = labelled_table(ref, sim, labels, groups, compiled=True)
        plain = labelled_table(ref, sim, labels, groups, compiled=False)
        bound = _rounding_bound(ref, sim, labels, plain)
    assert fast.scale == plain.scale
    assert fast.shift == plain.shift or (np.isnan(fast.shift) and np.isnan(plain.shift))
    assert np.array_equal(fast.values[:, [0, 9]], plain.values[:, [0, 9]])
    same_nan = np.isnan(fast.values) == np.isnan(plain.values)
    assert same_nan.all()
    with np.errstate(invalid="ignore"):
        apart = np.abs(fast.values - plain.values)
    assert np.all((apart <= bound) | np.isnan(plain.values))


@needs_kernel
@given(_labelled_pairs(), st.sampled_from([1, 3, 200, 1500]))
@settings(max_examples=60, deadline=None)
def test_the_main_pass_sums_the_groups_as_the_grouped_pass_does(
    case: tuple[np.ndarray, np.ndarray, np.ndarray, int], repeat: int
) -> None:
    """The groups' sums taken along with λ, chunk by chunk, are the standalone pass's to the
    bit, also when runs cross the chunks' edges (2^15 samples: records repeated 1,500 times)."""
    from pytest_hevval.core import kernel

    ref, sim, labels, groups = case
    ref, sim, labels = np.tile(ref, repeat), np.tile(sim, repeat), np.tile(labels, repeat)
    assume(np.isfinite(ref).all() and np.isfinite(sim).all())
    module = kernel.load_or_raise()
    grouping = Grouping.of(labels, (groups,))
    runs = grouping.runs(ref, sim)
    alone = kernel.grouped_sums(module, ref, sim, runs)
    _, along = kernel.main_pass(module, ref, sim, 1.0, 1, None, runs)
    assert along is not None
    assert along.tobytes() == alone.tobytes()


# -- through pytest and the command line ----------------------------------------------------


def test_a_grouping_keeps_the_runs_and_the_groups_the_record_visits() -> None:
    # Two axes of sizes 3 and 4: labels are 4·a + b; −1 is no group.
    labels = np.array([5, 5, 5, -1, -1, 0, 0, 5, 11, 11, 0], dtype=np.int64)
    grouping = Grouping.of(labels, (3, 4))
    assert grouping.starts.tolist() == [0, 5, 7, 8, 10]
    assert grouping.stops.tolist() == [3, 7, 8, 10, 11]
    # Only the visited groups, in label order: 0, 5, 11.
    assert grouping.digits.tolist() == [[0, 0], [1, 1], [2, 3]]
    assert grouping.run_group.tolist() == [1, 0, 1, 2, 0]
    assert grouping.group.tolist() == [1, 1, 1, -1, -1, 0, 0, 1, 2, 2, 0]
    assert grouping.samples == 9
    assert grouping.rows(0) == slice(0, 3)
    assert grouping.rows(1) == slice(3, 7)
    empty = Grouping.of(np.empty(0, dtype=np.int64), (2,))
    assert empty.groups == 0
    assert empty.samples == 0
    with pytest.raises(ValueError, match="beyond the grouping's 12 groups"):
        Grouping.of(np.array([12]), (3, 4))


@pytest.mark.parametrize("compiled", [False, pytest.param(True, marks=needs_kernel)])
def test_every_axis_adds_up_to_the_whole_record(compiled: bool) -> None:
    rng = np.random.default_rng(5)
    n = 5_000
    ref = np.cumsum(rng.normal(size=n))
    sim = ref + rng.normal(0, 0.3, n) + 1.0
    window, phase, cell = np.arange(n) // 400, rng.integers(0, 4, n) // 3, rng.integers(0, 7, n)
    grouping = Grouping.of((window * 2 + phase) * 7 + cell, (13, 2, 7))
    table = grouped_tables(ref, sim, grouping, compiled=compiled)
    whole = labelled_table(ref, sim, np.zeros(n, np.int64), 1, compiled=False).values[0]
    for axis in range(3):
        rows = table.values[grouping.rows(axis)]
        np.testing.assert_allclose(rows.sum(axis=0), whole, rtol=1e-12)
        assert rows[:, 0].sum() == n


def _trip_pair(n: int, factor: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(6)
    ref = (np.sin(np.arange(n) / 300.0) * 40.0 + rng.normal(0, 1.0, n)) * factor
    sim = (ref / factor * 0.97 + rng.normal(0, 0.5, n)) * factor
    labels = (np.arange(n) // 3000) * 5 + (np.abs(ref / factor) // 10).astype(np.int64)
    return ref, sim, labels


@needs_kernel
@pytest.mark.parametrize(
    ("n", "workers", "factor", "along"),
    [
        (100_000, 1, 1.0, True),  # summed in the main pass, chunk by chunk
        (100_000, 1, 2.0**450, True),  # squares overflow: summed again at a power-of-two scale
        (100_000, 1, 2.0**-450, True),  # squares underflow: the same
        (1 << 21, 2, 1.0, False),  # the main pass is shared between threads: a pass of its own
    ],
)
def test_the_groups_summed_along_with_lambda_are_the_grouped_pass(
    monkeypatch: pytest.MonkeyPatch, n: int, workers: int, factor: float, along: bool
) -> None:
    from pytest_hevval.core import kernel
    from pytest_hevval.core.characteristics import signal_characteristics

    monkeypatch.setenv(kernel.KERNEL_ENV, "numba")
    ref, sim, labels = _trip_pair(n, factor)
    grouping = Grouping.of(labels, (int(labels.max()) // 5 + 1, 5))
    chars = signal_characteristics(
        ref, sim, dt=0.01, max_lag_s=1.0, workers=workers, group_runs=grouping.runs(ref, sim)
    )
    assert (chars.group_sums is not None) == along
    with np.errstate(over="ignore", under="ignore"):
        fused = grouped_tables(ref, sim, grouping, summed=chars.group_sums)
    alone = grouped_tables(ref, sim, grouping, compiled=True)
    plain = grouped_tables(ref, sim, grouping, compiled=False)
    assert fused.values.tobytes() == alone.values.tobytes()
    assert (fused.shift, fused.scale) == (alone.shift, alone.scale) == (plain.shift, plain.scale)
    np.testing.assert_allclose(fused.values, plain.values, rtol=1e-9)


@needs_kernel
def test_the_engine_takes_the_windows_and_cells_from_the_main_pass(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With the kernel, a signal's windows and cells come from the pass that finds λ: the
    grouped pass of its own is never called, and the tables are those it would give."""
    from pytest_hevval.core import kernel

    monkeypatch.setenv(kernel.KERNEL_ENV, "numba")
    write_trip(tmp_path, stretch=True, fast=True)
    own_pass = kernel.grouped_sums
    expected = _evaluate(tmp_path).result.signals[0]  # type: ignore[attr-defined]

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the groups were summed in a pass of their own")

    monkeypatch.setattr(kernel, "grouped_sums", refuse)
    got = _evaluate(tmp_path).result.signals[0]  # type: ignore[attr-defined]
    assert got.local.to_dict() == expected.local.to_dict()
    monkeypatch.setattr(kernel, "grouped_sums", own_pass)
    monkeypatch.setenv(kernel.KERNEL_ENV, "numpy")
    on_numpy = _evaluate(tmp_path).result.signals[0]  # type: ignore[attr-defined]
    for scope in ("windows", "phases", "regions"):
        for name, values in getattr(on_numpy.local, scope).lambdas.items():
            np.testing.assert_allclose(
                getattr(got.local, scope).lambdas[name], values, rtol=1e-9, err_msg=name
            )


@pytest.mark.parametrize("xdist", [False, True])
def test_pytest_reports_the_windows_and_cells_that_missed(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, xdist: bool
) -> None:
    monkeypatch.delenv("CI", raising=False)
    write_trip(pytester.path, stretch=True, fast=True)
    pytester.makefile(".hevval.yaml", trip=SPEC)
    args = ["--hevval", "-p", "no:cacheprovider", "--hevval-report=json"]
    if xdist:
        args += ["-n", "2"]
    outcome = pytester.runpytest_subprocess(*args)
    outcome.assert_outcomes(failed=1, passed=1)
    text = outcome.stdout.str()
    assert "λ3 MAE ≥ 0.97 missed in " in text
    assert " of 60 windows" in text
    assert "1200–1230 s" in text
    assert "speed 100–120" in text
    assert "where: " in text
    (report,) = (pytester.path / ".hevval" / "report").glob("report.json")
    data = json.loads(report.read_text())
    (spec,) = data["specs"]
    assert spec["local"]["regions"]["labels"][5] == "speed 100–120"
    assert len(spec["signals"][0]["local"]["windows"]["n"]) == 60


def test_hevval_run_writes_windows_and_regions_to_json(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    write_trip(tmp_path, stretch=True, fast=False)
    (tmp_path / "trip.hevval.yaml").write_text(SPEC)
    monkeypatch.chdir(tmp_path)
    code = cli.main(["run", "trip.hevval.yaml", "--no-history", "--quiet", "--json", "out.json"])
    assert code == 1
    data = json.loads((tmp_path / "out.json").read_text())
    (spec,) = data.get("results", [data])
    local = spec["signals"][0]["local"]
    assert set(local) >= {"windows", "concentration", "phases", "conditions", "regions"}
    assert spec["signals"][0]["local_failures"][0]["where"] == ["1200–1230 s", "1230–1260 s"] or (
        set(spec["signals"][0]["local_failures"][0]["where"]) == {"1200–1230 s", "1230–1260 s"}
    )
    assert "mae <0.97 in 2 windows" in capsys.readouterr().out


def test_html_report_draws_the_strip_and_the_maps(tmp_path: Path) -> None:
    pytest.importorskip("jinja2")
    from pytest_hevval.report.html import render_html

    write_trip(tmp_path, stretch=True, fast=True)
    result = _evaluate(tmp_path).result  # type: ignore[attr-defined]
    page = render_html([result], title="t", generated_utc="now")
    assert "Where and when" in page
    assert 'aria-label="characteristics per time window"' in page
    assert "Φ per cell" in page
    assert "coverage: samples per cell" in page
    assert "Never visited: speed 140–160" in page
    assert page.count('stroke="#000" stroke-width="2"') == 2  # the two cells that missed


# -- history and compare --------------------------------------------------------------------


def test_compare_names_the_windows_and_cells_a_model_change_fixed(tmp_path: Path) -> None:
    from pytest_hevval.history.compare import compare
    from pytest_hevval.history.records import make_record
    from pytest_hevval.history.render import comparison_table

    before_dir, after_dir = tmp_path / "before", tmp_path / "after"
    before_dir.mkdir()
    after_dir.mkdir()
    write_trip(before_dir, stretch=True, fast=False)
    write_trip(after_dir, stretch=False, fast=True)
    before_result = _evaluate(before_dir).result  # type: ignore[attr-defined]
    after_result = _evaluate(after_dir).result  # type: ignore[attr-defined]
    before, after = before_result.to_dict(), after_result.to_dict()
    from datetime import datetime, timezone

    record = make_record([before], model_version="v1", started_utc=datetime.now(timezone.utc))
    kept = record["specs"][0]["signals"][0]["local"]
    assert "lambdas" not in kept["windows"]  # history keeps the windows' errors, not their λ
    assert kept["regions"]["lambdas"]["mae"]
    # A result reads alike typed, from its JSON and from the history record of it.
    typed = RecordedSpec.of(before_result)
    assert typed.signals[0].local["windows"]
    assert typed.signals[0].local["regions"]
    assert typed == RecordedSpec.from_json(before) == recorded(record).specs[0]
    comparison = compare([RecordedSpec.of(after_result)], recorded(record), pair_single=True)
    assert comparison == compare(recorded([after]), recorded(record), pair_single=True)
    (signal,) = comparison.specs[0].signals
    assert {c.label for c in signal.better if c.grouping == "windows"} == {
        "1200–1230 s",
        "1230–1260 s",
    }
    assert {c.label for c in signal.worse if c.grouping == "regions"} == {
        "speed 100–120",
        "speed 120–140",
    }
    text = comparison_table(comparison)
    assert "better in: 1200–1230 s" in text or "better in: 1230–1260 s" in text
    assert "worse in:" in text


def test_a_recorded_run_with_windows_reads_back_for_evidence_and_trace(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A history record keeps the windows without their λ; `hevval evidence` and `hevval
    trace` read the newest record back as results, windows and all."""
    from datetime import datetime, timezone

    from pytest_hevval.cli import main
    from pytest_hevval.history import HistoryStore, make_record
    from pytest_hevval.results.spec_result import SpecResult

    write_trip(tmp_path, stretch=True, fast=False)
    spec_text = SPEC.replace("name: localised", "name: localised\nrequirements: [REQ-1]")
    result = _evaluate(tmp_path, spec_text).result  # type: ignore[attr-defined]
    record = make_record(
        [result.to_dict()], model_version="v1", started_utc=datetime.now(timezone.utc)
    )
    HistoryStore(tmp_path / ".hevval" / "history").append(record)
    read = SpecResult.from_dict(record["specs"][0])
    windows = read.signals[0].local.windows  # type: ignore[union-attr]
    assert windows.labels == result.signals[0].local.windows.labels
    assert list(windows.rms) == pytest.approx(list(result.signals[0].local.windows.rms))
    assert not windows.lambdas  # the record keeps no window λ
    monkeypatch.chdir(tmp_path)
    assert main(["evidence", "--output", "evidence.json"]) == 0
    assert json.loads((tmp_path / "evidence.json").read_text())["run"]["model_version"] == "v1"
    capsys.readouterr()
    main(["trace"])
    out = capsys.readouterr()
    assert "REQ-1" in out.out
    assert "Traceback" not in out.err
