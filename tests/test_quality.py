"""The data-quality gate: real logger faults from the i3 data, and each kind of finding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval.data.quality import Finding, QualityLimits, assess
from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import Channel, Record, SourceOptions
from pytest_hevval.errors import DataError, SpecError
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import parse_spec_text
from tests.conftest import needs_kernel
from tests.strategies import logged_channels

DATA = Path(__file__).parent / "data" / "i3"
B02 = DATA / "TripB02_0-400s.parquet"
B34 = DATA / "TripB34_0-400s.parquet"
pytest.importorskip("pyarrow")


def _findings(
    path: Path, columns: list[str], **limits: object
) -> list[tuple[str, str, float, float]]:
    record = read_record(str(path), columns, SourceOptions(time="Time [s]"))
    found = assess(record, columns, QualityLimits(**limits))  # type: ignore[arg-type]
    return [(f.channel, f.kind, f.start_s, f.stop_s) for f in found]


def test_b02_straight_line_fill_is_found_on_every_channel_it_touched(kernel_path: str) -> None:
    columns = ["Velocity [km/h]", "Battery Voltage [V]", "Battery Current [A]"]
    found = _findings(B02, columns)
    assert found == [
        (name, "straight-line fill", pytest.approx(39.3), pytest.approx(199.1)) for name in columns
    ]


def test_b34_nan_run_in_soc_is_found(kernel_path: str) -> None:
    found = _findings(B34, ["Velocity [km/h]", "SoC [%]"])
    assert found == [("SoC [%]", "NaN run", pytest.approx(293.1), pytest.approx(400.0))]


def _record(**channels: tuple[np.ndarray, np.ndarray]) -> Record:
    return Record(source="log.csv", channels={k: Channel(t, v) for k, (t, v) in channels.items()})


def test_each_kind_of_finding(kernel_path: str) -> None:
    t = np.arange(0.0, 1000.0, 0.1)
    rng = np.random.default_rng(0)
    noisy = 50.0 + rng.normal(0.0, 1.0, t.shape[0])
    stuck = noisy.copy()
    stuck[2000:9000] = 42.0  # 700 s at one non-zero value
    at_rest = noisy.copy()
    at_rest[2000:9000] = 0.0  # a long stop: not a stuck sensor
    clipped = np.minimum(noisy, 51.5)
    clipped[1000:1200] = 51.5
    clipped[5000:5200] = 51.5  # held at the top twice
    spiky = noisy.copy()
    spiky[4000] += 500.0
    gap_t = np.concatenate([t[:3000], t[3100:]])  # 10 s without samples
    record = _record(
        stuck=(t, stuck),
        at_rest=(t, at_rest),
        clipped=(t, clipped),
        spiky=(t, spiky),
        gappy=(gap_t, noisy[: gap_t.shape[0]]),
    )
    limits = QualityLimits(rate_limits={"spiky": 1000.0})
    found: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for f in assess(record, record.channels, limits):
        found.setdefault((f.channel, f.kind), []).append((f.start_s, f.stop_s))
    assert found.pop(("stuck", "flat line")) == [pytest.approx((200.0, 899.9))]
    clipped_runs = found.pop(("clipped", "saturation"))
    assert len(clipped_runs) == 2
    assert clipped_runs[0] == pytest.approx((100.0, 119.9), abs=0.2)
    assert clipped_runs[1] == pytest.approx((500.0, 519.9), abs=0.2)
    assert found.pop(("spiky", "spike")) == [pytest.approx((399.9, 400.1))]  # up and back
    assert found.pop(("gappy", "time gap")) == [pytest.approx((299.9, 310.0))]
    assert found == {}  # nothing on the channel at rest, nothing else anywhere


SPEC = """\
reference: {{path: ref.parquet, time: "Time [s]"}}
model: {{path: sim.csv, time: "Time [s]"}}
data_quality: {{action: {action}}}
sets:
  - {{signal: v, ref: "Velocity [km/h]", sim: "Velocity [km/h]"}}
"""


def _project(tmp_path: Path) -> None:
    frame = pd.read_parquet(B02)
    frame.to_parquet(tmp_path / "ref.parquet", index=False)
    frame[["Time [s]", "Velocity [km/h]"]].to_csv(tmp_path / "sim.csv", index=False)


def test_error_blames_the_measurement_with_channel_and_time(tmp_path: Path) -> None:
    _project(tmp_path)
    spec = parse_spec_text(SPEC.format(action="error"), tmp_path / "t.hevval.yaml")
    with pytest.raises(DataError) as caught:
        evaluate_spec(spec)
    assert str(caught.value) == (
        f"{tmp_path / 'ref.parquet'}: column 'Velocity [km/h]': the measurement is at fault, "
        "not the model: straight-line fill at 39.3–199.1 s (changes at a constant rate for "
        "over 20 s, as a logger filling a dropout writes); fix or cut the recording, or set "
        "data_quality.action: omit to score around it"
    )


def test_warn_reports_and_omit_scores_around(tmp_path: Path) -> None:
    _project(tmp_path)
    warned = evaluate_spec(parse_spec_text(SPEC.format(action="warn"), tmp_path / "w.hevval.yaml"))
    quality = warned.result.data.quality
    assert quality is not None
    assert quality.action == "warn"
    assert [f.kind for f in quality.findings] == ["straight-line fill"]
    assert warned.result.alignment.coverage == 1.0
    omitted = evaluate_spec(parse_spec_text(SPEC.format(action="omit"), tmp_path / "o.hevval.yaml"))
    # 39.3–199.1 s of a 400 s record are left out: 1599 of 4001 grid points.
    assert omitted.result.alignment.coverage == pytest.approx(1 - 1599 / 4001)
    assert omitted.result.signals[0].characteristics.n_samples == 4001 - 1599


def test_bad_data_quality_keys_are_spec_errors(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"data_quality\.action: must be one of warn, omit, error"):
        parse_spec_text(SPEC.format(action="ignore"), tmp_path / "t.hevval.yaml")
    text = SPEC.format(action="warn").replace("{action: warn}", "{max_gap: 3}")
    with pytest.raises(SpecError, match="unknown key; did you mean 'max_gap_s'"):
        parse_spec_text(text, tmp_path / "t.hevval.yaml")


def test_the_terminal_summary_lists_the_findings(pytester: pytest.Pytester) -> None:
    _project(pytester.path)
    pytester.makefile(".hevval.yaml", trip=SPEC.format(action="warn"))
    result = pytester.runpytest("--hevval", "-p", "no:cacheprovider")
    result.stdout.fnmatch_lines(
        [
            "*data quality: 1 finding(s) in the measurement*",
            "*Velocity [[]km/h[]]: straight-line fill at 39.3–199.1 s*",
        ]
    )


def test_reports_show_the_findings(tmp_path: Path) -> None:
    pytest.importorskip("jinja2")
    from pytest_hevval.report.html import render_html
    from pytest_hevval.report.text import render_markdown

    _project(tmp_path)
    result = evaluate_spec(parse_spec_text(SPEC.format(action="warn"), tmp_path / "w.hevval.yaml"))
    payload = [result.result]
    assert "Velocity [km/h]: straight-line fill at 39.3–199.1 s" in render_html(
        payload, title="t", generated_utc="now"
    )
    markdown = render_markdown(payload)
    assert "**Data quality of" in markdown
    assert "straight-line fill at 39.3–199.1 s" in markdown


def test_a_shared_time_array_is_examined_once(monkeypatch: pytest.MonkeyPatch) -> None:
    from pytest_hevval.data import quality

    examined: list[int] = []
    real = quality._time_spans

    def counted(time: np.ndarray, limits: QualityLimits) -> object:
        examined.append(time.shape[0])
        return real(time, limits)

    monkeypatch.setattr(quality, "_time_spans", counted)
    shared = np.concatenate([np.arange(0.0, 100.0, 0.1), np.arange(110.0, 200.0, 0.1)])
    own = np.arange(0.0, 50.0, 0.1)
    rng = np.random.default_rng(1)
    record = _record(
        **{f"s{i}": (shared, rng.normal(0.0, 1.0, shared.shape[0])) for i in range(6)},
        own=(own, rng.normal(0.0, 1.0, own.shape[0])),
    )
    for threads in (1, 2):
        examined.clear()
        found = assess(record, record.channels, QualityLimits(), threads=threads)
        assert sorted(examined) == [own.shape[0], shared.shape[0]]
        # ... yet every channel on the shared time array reports its gap, in channel order.
        assert [(f.channel, f.kind) for f in found] == [(f"s{i}", "time gap") for i in range(6)]
        assert {(f.start_s, f.stop_s) for f in found} == {(float(shared[999]), 110.0)}


def test_findings_do_not_depend_on_the_thread_count() -> None:
    t = np.arange(0.0, 1000.0, 0.1)
    rng = np.random.default_rng(2)
    channels = {}
    for i in range(8):
        values = 50.0 + rng.normal(0.0, 1.0, t.shape[0])
        values[1000 * i : 1000 * i + 300] = np.nan
        values[5000 : 5000 + 500 * i] = 42.0
        channels[f"c{i}"] = (t, values)
    record = _record(**channels)
    limits = QualityLimits(flat_run_s=20.0)
    one = assess(record, record.channels, limits, threads=1)
    assert {f.kind for f in one} == {"NaN run", "flat line"}
    assert assess(record, record.channels, limits, threads=2) == one
    assert assess(record, record.channels, limits, threads=3) == one


@needs_kernel
@given(
    logged_channels(),
    st.sampled_from([0.0, 0.3, 2.0]),
    st.sampled_from([0.0, 0.5, 3.0]),
    st.sampled_from([0.0, 0.2, 1.0]),
)
@settings(max_examples=150, deadline=None)
def test_the_compiled_scan_finds_what_the_numpy_scan_finds(
    channel: tuple[np.ndarray, np.ndarray], straight_s: float, flat_s: float, saturation_s: float
) -> None:
    from pytest_hevval.core import kernel
    from pytest_hevval.data import quality

    time, values = channel
    limits = QualityLimits(
        straight_run_s=straight_s, flat_run_s=flat_s, saturation_run_s=saturation_s
    )
    spans = quality._time_spans(time, limits)
    compiled = kernel.load_or_raise()
    plain = quality._channel_findings("c", time, values, True, limits, "V", spans, None)
    fast = quality._channel_findings("c", time, values, True, limits, "V", spans, compiled)
    assert fast == plain


@needs_kernel
def test_the_compiled_scan_lists_more_runs_than_it_first_makes_room_for() -> None:
    from pytest_hevval.core import kernel
    from pytest_hevval.data import quality

    time = np.arange(0.0, 200.0, 0.1)
    values = np.tile(np.repeat([1.0, 2.0, 3.0, 4.0], 5), 100)  # 400 holds of 0.4 s
    limits = QualityLimits(flat_run_s=0.3, saturation_run_s=0.3)
    spans = quality._time_spans(time, limits)
    compiled = kernel.load_or_raise()
    plain = quality._channel_findings("c", time, values, True, limits, None, spans, None)
    fast = quality._channel_findings("c", time, values, True, limits, None, spans, compiled)
    assert fast == plain
    flat = [f.detail for f in plain if f.kind == "flat line"]
    assert flat[-1] == "and 395 more stretches like it"
    assert "100 times" in next(f.detail for f in plain if f.kind == "saturation")


@needs_kernel
@pytest.mark.parametrize("path", sorted(DATA.glob("*.parquet")), ids=lambda p: p.stem)
def test_the_compiled_scan_finds_what_the_numpy_scan_finds_on_real_trips(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every numeric channel of each i3 trip, with the default limits and with limits short
    enough that flat lines are found on every trip (B02 also has straight-line fill)."""
    from pytest_hevval.core.kernel import KERNEL_ENV

    frame = pd.read_parquet(path)
    columns = [c for c in frame.columns if c != "Time [s]" and frame[c].dtype.kind == "f"]
    record = read_record(str(path), columns, SourceOptions(time="Time [s]"))
    settings = (QualityLimits(), QualityLimits(straight_run_s=2.0, flat_run_s=5.0))
    found: dict[str, list[list[Finding]]] = {}
    for kernel in ("numpy", "numba"):
        monkeypatch.setenv(KERNEL_ENV, kernel)
        found[kernel] = [assess(record, columns, limits) for limits in settings]
    assert found["numba"] == found["numpy"]
    assert "flat line" in {f.kind for f in found["numpy"][1]}
