"""One common time grid: rates, windows, offsets, interpolation, gaps and units."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pytest_hevval.core.kernel import KERNEL_ENV
from pytest_hevval.data.align import _Plan, align_records, nominal_rate
from pytest_hevval.data.record import Channel, Record
from pytest_hevval.errors import DataError
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import parse_spec_text
from tests.conftest import _kernel_unavailable


def record(name: str, time: np.ndarray, **columns: np.ndarray) -> Record:
    return Record(
        source=name,
        channels={k: Channel(time=time, values=v) for k, v in columns.items()},
        available=tuple(columns),
    )


def test_default_grid_is_the_reference_rate_over_the_overlap() -> None:
    ref = record("ref.csv", np.arange(0, 100, 0.1), x=np.arange(1000.0))
    sim = record("sim.csv", np.arange(5, 200, 1.0), x=np.arange(195.0))
    aligned = align_records(ref, sim, reference_columns=["x"], model_columns=["x"])
    assert aligned.grid.rate_hz == pytest.approx(10.0)
    assert aligned.grid.start_s == 5.0
    assert aligned.grid.stop_s == pytest.approx(99.9)
    assert aligned.grid.n_samples == 950


def test_linear_and_zero_order_hold() -> None:
    time = np.array([0.0, 1.0, 2.0, 3.0])
    ref = record("ref.csv", np.arange(0, 3.01, 0.5), gear=np.arange(7.0))
    sim = record("sim.csv", time, gear=np.array([1.0, 2.0, 3.0, 4.0]))
    aligned = align_records(ref, sim, reference_columns=["gear"], model_columns=["gear"])
    assert list(aligned.column("model", "gear", "linear")) == [1, 1.5, 2, 2.5, 3, 3.5, 4]
    assert list(aligned.column("model", "gear", "previous")) == [1, 1, 2, 2, 3, 3, 4]


def test_declared_rate_and_window() -> None:
    ref = record("ref.csv", np.arange(0, 100, 0.01), x=np.zeros(10_000))
    sim = record("sim.csv", np.arange(0, 100, 0.01), x=np.zeros(10_000))
    aligned = align_records(
        ref, sim, reference_columns=["x"], model_columns=["x"], rate_hz=2, window=(10, 20)
    )
    assert aligned.grid.n_samples == 21
    assert aligned.time[0] == 10.0


def test_declared_offset_shifts_the_model() -> None:
    t = np.arange(0, 50, 0.1)
    ref = record("ref.csv", t, x=np.sin(t))
    sim = record("sim.csv", t + 2.0, x=np.sin(t))  # the model's clock runs 2 s late
    aligned = align_records(ref, sim, reference_columns=["x"], model_columns=["x"], offset_s=-2.0)
    np.testing.assert_allclose(aligned.column("model", "x", "linear"), aligned.column(
        "reference", "x", "linear"
    ), atol=1e-12)  # fmt: skip


def test_offset_found_by_cross_correlating_speed() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(0, 300, 0.1)
    speed = np.convolve(rng.normal(size=t.size), np.ones(30) / 30, "same") * 20 + 30
    ref = record("ref.csv", t, v=speed)
    sim = record("sim.csv", t + 2.5, v=speed)
    aligned = align_records(
        ref, sim, reference_columns=["v"], model_columns=["v"], offset_from=("v", "v")
    )
    assert aligned.offset_found
    assert aligned.offset_s == pytest.approx(-2.5)


def test_no_overlap_is_a_clear_error() -> None:
    ref = record("ref.csv", np.arange(0, 10, 0.1), x=np.zeros(100))
    sim = record("sim.csv", np.arange(20, 30, 0.1), x=np.zeros(100))
    with pytest.raises(DataError) as info:
        align_records(ref, sim, reference_columns=["x"], model_columns=["x"])
    assert str(info.value) == (
        "sim.csv: the reference and the model output do not overlap in time "
        "(reference 0–9.9 s, model 20–29.9 s); check both time columns, their units "
        "(time_scale) and alignment.offset_s"
    )


def test_window_outside_the_overlap() -> None:
    ref = record("ref.csv", np.arange(0, 10, 0.1), x=np.zeros(100))
    sim = record("sim.csv", np.arange(0, 10, 0.1), x=np.zeros(100))
    with pytest.raises(DataError, match=r"window \[5, 50\] s is not covered by both records"):
        align_records(ref, sim, reference_columns=["x"], model_columns=["x"], window=(5, 50))


def test_nan_raise_and_omit() -> None:
    t = np.arange(0, 10, 0.1)
    values = np.ones(100)
    values[40:45] = np.nan
    ref = record("ref.csv", t, x=values)
    sim = record("sim.csv", t, x=np.ones(100))
    strict = align_records(ref, sim, reference_columns=["x"], model_columns=["x"])
    with pytest.raises(DataError) as info:
        strict.column("reference", "x", "linear")
    assert str(info.value) == (
        "ref.csv: column 'x': 5 NaN or inf values (first at t = 4 s); "
        "set alignment.nan: omit to score only where data exists"
    )
    lenient = align_records(
        ref, sim, reference_columns=["x"], model_columns=["x"], nan_policy="omit"
    )
    lenient.column("reference", "x", "linear")
    assert lenient.gap_mask is not None
    # Exactly the 5 bad samples: on the exact 10 Hz grid the good sample after them is a grid
    # point of its own, not a point a rounding-drifted grid put inside the gap.
    assert np.flatnonzero(lenient.gap_mask).tolist() == [40, 41, 42, 43, 44]
    assert lenient.coverage == pytest.approx(0.95)


def test_each_column_is_checked_for_nan_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """The data-quality checks and the alignment both ask whether a column is finite; on a long
    record each asking is a read of the column, so it is answered once per channel."""
    from pytest_hevval.data import record as record_module
    from pytest_hevval.data.quality import QualityLimits, assess

    asked: list[int] = []
    real = record_module.all_finite

    def counted(values: np.ndarray) -> bool:
        asked.append(id(values))
        return real(values)

    monkeypatch.setattr(record_module, "all_finite", counted)
    t = np.arange(0, 10, 0.1)
    bad = np.sin(t)
    bad[7] = np.inf
    ref = record("ref.csv", t, x=np.sin(t), y=np.cos(t), z=bad)
    sim = record("sim.csv", t, x=np.sin(t), y=np.cos(t), z=np.sin(t))
    assess(ref, ["x", "y", "z"], QualityLimits(), threads=2)
    aligned = align_records(ref, sim, reference_columns=["x", "y", "z"], model_columns=["x", "y"])
    for side, name in [("reference", "x"), ("reference", "y"), ("model", "x"), ("model", "y")]:
        aligned.column(side, name, "linear")  # type: ignore[arg-type]
    with pytest.raises(DataError, match="1 NaN or inf values"):
        aligned.column("reference", "z", "linear")
    assert sorted(asked) == sorted(
        id(r.channels[n].values) for r, names in ((ref, "xyz"), (sim, "xy")) for n in names
    )


def test_units_are_converted_with_pint(tmp_path: Path) -> None:
    pytest.importorskip("pint")
    t = np.arange(0, 60, 0.5)
    energy_kwh = np.cumsum(np.abs(np.sin(t))) * 0.01
    pd.DataFrame({"time": t, "E": energy_kwh}).to_csv(tmp_path / "ref.csv", index=False)
    pd.DataFrame({"time": t, "E": energy_kwh * 3.6e6}).to_csv(tmp_path / "sim.csv", index=False)
    text = (
        "reference: ref.csv\nmodel: {path: sim.csv}\n"
        "sets:\n  - {signal: E, unit: kWh, sim_unit: J}\n"
    )
    spec = parse_spec_text(text, tmp_path / "u.hevval.yaml")
    result = evaluate_spec(spec).result
    assert result.signals[0].mae == pytest.approx(0.0, abs=1e-12)
    # A J → kWh conversion may leave an ulp, so λ3 = 1 − MAE/R is 1 to within rounding.
    assert result.signals[0].lambdas["mae"] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize(
    ("step", "expected"),
    [
        (0.09999999999997726, 10.0),  # decimal time stamps 0.0, 0.1, … as read from a file
        (0.01, 100.0),
        (0.010000000000218279, 100.0),
        (3.0, 1.0 / 3.0),  # the step is the short decimal: 1/3 Hz, not 0.333333 Hz
        (0.0123456789, 1.0 / 0.0123456789),  # neither is a short decimal: as measured
    ],
)
def test_nominal_rate(step: float, expected: float) -> None:
    assert nominal_rate(step) == expected


I3_TRIPS = sorted((Path(__file__).parents[1] / "example_project" / "data" / "i3").glob("*.parquet"))


@pytest.mark.parametrize("trip", I3_TRIPS, ids=[p.stem for p in I3_TRIPS])
def test_real_trips_keep_every_row_and_interpolate_nothing(trip: Path) -> None:
    """Decimal time stamps (0.0, 0.1, …): a 10 Hz grid, every sample kept, values as logged."""
    pytest.importorskip("pyarrow")
    from pytest_hevval.data.readers import read_record
    from pytest_hevval.data.record import SourceOptions

    columns = ["Velocity [km/h]", "Battery Current [A]", "Battery Voltage [V]"]
    recorded = read_record(str(trip), columns, SourceOptions(time="Time [s]"))
    rows = recorded.channels[columns[0]].time.shape[0]
    aligned = align_records(recorded, recorded, reference_columns=columns, model_columns=columns)
    assert aligned.grid.rate_hz == 10.0
    assert aligned.grid.n_samples == rows
    for name in columns:
        for side in ("reference", "model"):
            values = aligned.column(side, name, "linear")
            assert values is recorded.channels[name].values or np.array_equal(
                values, recorded.channels[name].values
            )
    assert aligned.interpolated == []


def test_channels_sharing_a_time_base_share_one_interpolation_plan() -> None:
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 100.0, 2000))  # off any grid
    columns = {f"c{i}": rng.normal(size=2000) for i in range(5)}
    ref = record("ref.csv", np.arange(0.0, 100.0, 0.05), x=np.zeros(2000))
    sim = record("sim.csv", t, **columns)
    aligned = align_records(ref, sim, reference_columns=["x"], model_columns=list(columns))
    for method in ("linear", "previous"):
        for name, values in columns.items():
            got = aligned.column("model", name, method)  # type: ignore[arg-type]
            if method == "linear":
                expected = np.interp(aligned.time, t, values)
            else:
                index = np.clip(np.searchsorted(t, aligned.time, side="right") - 1, 0, 1999)
                expected = values[index]
            np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)
    assert len(aligned._plans) == 2  # one per method, not one per column
    assert len(aligned.interpolated) == 10


@pytest.mark.parametrize("n", [20_000, 300_001])  # one chunk on one thread; chunks on two
def test_an_interpolation_plan_rounds_as_np_interp(kernel_path: str, n: int) -> None:
    """On either path (numpy, or the compiled kernel) a plan gives np.interp's very bits,
    also where a time stamp falls on a grid point and beyond either end of the record."""
    rng = np.random.default_rng(5)
    t = np.arange(n) * 0.01 + rng.uniform(-0.002, 0.002, n)  # jitter: off the grid
    t[5::7] = np.arange(n)[5::7] * 0.01  # some exactly on it
    columns = {f"c{i}": np.cumsum(rng.normal(size=n)) for i in range(3)}
    ref = record("ref.csv", np.arange(n) * 0.01, x=np.zeros(n))
    sim = record("sim.csv", t, **columns)
    aligned = align_records(ref, sim, reference_columns=["x"], model_columns=list(columns))
    for name, values in columns.items():
        got = aligned.column("model", name, "linear")
        np.testing.assert_array_equal(got, np.interp(aligned.time, t, values))
    assert len(aligned.interpolated) == 3


@st.composite
def _time_bases(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid points and the time stamps of a logger on another clock: jittered, some exactly on
    grid points, starting before or after the grid and ending before or after it; values with
    zeros of both signs, so that a point which takes its sample as it is must keep its sign."""
    n = draw(st.integers(2, 120))
    jitter = draw(hnp.arrays(np.float64, n, elements=st.floats(-0.45, 0.45)))
    exact = draw(hnp.arrays(np.bool_, n))
    start = draw(st.sampled_from([-3, 0, 2]))
    time = (np.arange(n) + start + np.where(exact, 0.0, jitter)) * 0.1
    time = np.unique(time)
    values = draw(
        hnp.arrays(
            np.float64,
            time.shape[0],
            elements=st.one_of(st.sampled_from([0.0, -0.0]), st.floats(-1e6, 1e6)),
        )
    )
    grid = np.arange(draw(st.integers(3, 130))) * 0.1
    return grid, time, values


@given(_time_bases())
@settings(max_examples=200, deadline=None)
def test_a_plan_gives_np_interps_very_bits(case: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """Bit for bit, the sign of zero included, on the numpy path and the compiled one."""
    grid, time, values = case
    expected = np.interp(grid, time, values)
    plan = _Plan.build(time, 0.0, grid, "linear")
    paths = ["numpy"] + (["numba"] if _kernel_unavailable() is None else [])
    for path in paths:
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv(KERNEL_ENV, path)
            single = plan.apply(values)
            many = plan.apply_all([values, -values])
        assert single.tobytes() == expected.tobytes(), path
        assert many[0].tobytes() == expected.tobytes(), path
        assert many[1].tobytes() == np.interp(grid, time, -values).tobytes(), path


def test_columns_of_one_time_base_are_interpolated_together(kernel_path: str) -> None:
    """Asking for one column interpolates the other declared columns of its time base with it;
    each is served when asked for, only then counted as interpolated, and a column with NaN
    still goes its own way (its error, or its gaps)."""
    rng = np.random.default_rng(11)
    n = 5000
    t = np.arange(n) * 0.01 + rng.uniform(-0.003, 0.003, n)
    columns = {f"c{i}": np.cumsum(rng.normal(size=n)) for i in range(4)}
    columns["bad"] = np.ones(n)
    columns["bad"][100] = np.nan
    other_time = np.arange(n) * 0.01 + 0.004  # another time base: not interpolated with them
    ref = record("ref.csv", np.arange(n) * 0.01, x=np.zeros(n))
    sim = Record(
        source="sim.csv",
        channels={
            **{k: Channel(time=t, values=v) for k, v in columns.items()},
            "other": Channel(time=other_time, values=np.arange(n, dtype=np.float64)),
        },
        available=(*columns, "other"),
    )
    names = [*columns, "other"]
    aligned = align_records(ref, sim, reference_columns=["x"], model_columns=names)
    first = aligned.column("model", "c0", "linear")
    np.testing.assert_array_equal(first, np.interp(aligned.time, t, columns["c0"]))
    assert aligned.interpolated == [("model", "c0")]
    assert sorted(key[1] for key in aligned._prepared) == ["c1", "c2", "c3"]
    for name in ("c3", "c1", "c2"):
        got = aligned.column("model", name, "linear")
        np.testing.assert_array_equal(got, np.interp(aligned.time, t, columns[name]))
    assert aligned._prepared == {}
    assert aligned.interpolated == [("model", n) for n in ("c0", "c3", "c1", "c2")]
    # The hold of another method is its own plan, over the same columns.
    held = aligned.column("model", "c2", "previous")
    index = np.clip(np.searchsorted(t, aligned.time, side="right") - 1, 0, n - 1)
    np.testing.assert_array_equal(held, columns["c2"][index])
    with pytest.raises(DataError, match="1 NaN or inf values"):
        aligned.column("model", "bad", "linear")
    np.testing.assert_array_equal(
        aligned.column("model", "other", "linear"),
        np.interp(aligned.time, other_time, sim.channels["other"].values),
    )


# --- off-grid columns put on the grid where they are scored --------------------------------

DEFERRED_SPEC = """\
name: deferred
reference: {path: ref.parquet, time: t}
model: {path: sim.parquet, time: t}
alignment: {max_lag_s: 1, nan: omit}
local: {window_s: 20}
regions: {by: [c0], bins: [4]}
metrics: [nse, iso18571]
sets:
  - signal: c0
    children:
      - {signal: c1}
      - {signal: c2}
      - {signal: c3, sim: "c3 * 2"}
      - {signal: c4, sim_unit: kW, ref_unit: kW, unit: W}
"""


def _deferred_files(folder: Path, n: int, gap: bool) -> None:
    rng = np.random.default_rng(5)
    t = np.arange(n) * 0.01
    ref = {f"c{i}": np.cumsum(rng.normal(size=n)) + 50.0 for i in range(5)}
    pd.DataFrame({"t": t, **ref}).to_parquet(folder / "ref.parquet")
    jittered = t + rng.uniform(-0.003, 0.003, n)
    sim = {k: v + rng.normal(scale=0.5, size=n) for k, v in ref.items()}
    if gap:
        sim["c2"][n // 3 : n // 3 + 40] = np.nan
    pd.DataFrame({"t": jittered, **sim}).to_parquet(folder / "sim.parquet")


def _scored(folder: Path, deferred: bool, monkeypatch: pytest.MonkeyPatch) -> dict[str, object]:
    from pytest_hevval.data.align import AlignedData

    with monkeypatch.context() as patch:
        if not deferred:
            patch.setattr(AlignedData, "deferred_column", lambda *args: None)
        spec = parse_spec_text(DEFERRED_SPEC, folder / "deferred.hevval.yaml")
        evaluation = evaluate_spec(spec, figures=True, workers=2)
    cached = {key[1] for key in evaluation.aligned._cache if key[0] == "model"}
    return {"result": evaluation.result.to_dict(), "cached": cached}


@pytest.mark.parametrize("n", [6000, 70_000], ids=["stacked-blocks", "blocks-per-signal"])
@pytest.mark.parametrize("gap", [False, True], ids=["whole", "gap"])
def test_off_grid_columns_scored_where_used_give_the_same_results(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kernel_path: str, n: int, gap: bool
) -> None:
    """A model column off the grid is put on it in the scoring pass, into a buffer each thread
    reuses, instead of a full-length copy per column: λ, intervals, windows and regions,
    standard metrics and figures are those of the copies, bit for bit, on both kernel paths,
    with the fine blocks summed per signal or as a stack, and with a gap (then every signal is
    copied around it, as before)."""
    _deferred_files(tmp_path, n, gap)
    scored = _scored(tmp_path, True, monkeypatch)
    copied = _scored(tmp_path, False, monkeypatch)
    assert scored["result"] == copied["result"]
    assert copied["cached"] == {"c0", "c1", "c2", "c3", "c4"}
    # Kept in full: the expression's column (c3 * 2), the converted one and the one with NaN.
    assert scored["cached"] == ({"c2", "c3", "c4"} if gap else {"c3", "c4"})


def test_fine_blocks_summed_in_the_scoring_pass_give_the_intervals_of_a_pass_of_their_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kernel_path: str
) -> None:
    """A long record's fine-block sums are taken on the signal's scoring thread; summed after
    every signal instead (as records short enough to stack are), the intervals are the same."""
    import pytest_hevval.scoring.signal_pass as signal_pass

    _deferred_files(tmp_path, 70_000, False)
    in_pass = _scored(tmp_path, True, monkeypatch)["result"]
    with monkeypatch.context() as patch:
        patch.setattr(signal_pass, "block_sums_stacked", lambda n: True)
        afterwards = _scored(tmp_path, True, monkeypatch)["result"]
    assert in_pass == afterwards
    signals = in_pass["signals"]  # type: ignore[index]
    assert all(signal["intervals"] for signal in signals)
