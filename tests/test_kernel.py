"""The compiled kernel against the numpy reference path, and how a path is chosen."""

from __future__ import annotations

import collections
import math
import os
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings

from pytest_hevval import signal_characteristics
from pytest_hevval.core import kernel
from pytest_hevval.core.characteristics import SignalCharacteristics
from pytest_hevval.core.groups import LOCAL_CHARACTERISTICS, Grouping, labelled_table
from pytest_hevval.data import kernel_cache
from pytest_hevval.errors import DegenerateSignalError, HevvalError
from tests.conftest import _kernel_unavailable, needs_kernel
from tests.strategies import signal_pairs

ROOT = Path(__file__).resolve().parents[1]
TRIPS = sorted((ROOT / "example_project" / "data" / "i3").glob("*.parquet"))


def _on(
    path: str, monkeypatch: pytest.MonkeyPatch, *args: np.ndarray, **kw: object
) -> SignalCharacteristics:
    monkeypatch.setenv(kernel.KERNEL_ENV, path)
    return signal_characteristics(*args, **kw)  # type: ignore[arg-type]


def _assert_agree(a: SignalCharacteristics, b: SignalCharacteristics, lag: bool = True) -> None:
    """Agreement to 1e-12 relative. A quantity that is a small difference of large ones is
    held to 1e-12 of the scale it was computed at: λ = 1 − E/R to 1e-12 of 1, the mean error
    and ΔE to 1e-12 of the RMS error, the peak correlation (a sum of centred products, which
    cancel where the reference is one spike) to 1e-12 of its bound 1."""
    if lag:
        assert a.lag_s == b.lag_s
        assert a.peak_correlation == pytest.approx(b.peak_correlation, rel=1e-12, abs=1e-12)
    assert a.n_samples == b.n_samples
    # λ5 = 1 − ΔE/R, and ΔE is held to 1e-12 of the RMS error below: so λ5 to 1e-12 of RMS/R.
    anomaly_scale = max(1.0, a.rms / a.reference_range)
    for name, x, y in zip(LOCAL_CHARACTERISTICS, a.lambdas, b.lambdas, strict=True):
        tolerance = 1e-12 * (anomaly_scale if name == "anomaly" else 1.0)
        assert x == pytest.approx(y, rel=1e-12, abs=tolerance), name
    for name in ("mae", "rms", "error_std", "reference_range"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-12, abs=1e-300), name
    assert a.delta_e == pytest.approx(b.delta_e, rel=1e-12, abs=1e-12 * a.rms)
    assert a.mean_error == pytest.approx(b.mean_error, rel=1e-12, abs=1e-12 * a.rms)


@needs_kernel
@given(signal_pairs(max_size=2000))
@settings(max_examples=60, deadline=None)
def test_kernel_agrees_with_numpy_on_random_pairs(pair: tuple[np.ndarray, np.ndarray]) -> None:
    # A constant simulation has no timing: its lag is decided by the last bit of its mean,
    # which the two paths round differently. Its λ values are still compared below.
    simulated = pair[1]
    timed = np.ptp(simulated) > 1e-6 * (np.abs(simulated).max() + 1)
    with pytest.MonkeyPatch.context() as patch:
        reference = _on("numpy", patch, *pair, dt=0.1)
        compiled = _on("numba", patch, *pair, dt=0.1)
    _assert_agree(reference, compiled, lag=timed)


@needs_kernel
@pytest.mark.parametrize("n", [300_001, 1_000_003])  # pyramid lag path, odd chunk tails
def test_kernel_agrees_with_numpy_on_long_records(n: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(n)
    reference = np.cumsum(rng.normal(size=n)) + 50.0
    simulated = np.roll(reference, 9) * 1.01 + rng.normal(0.3, 0.5, size=n)
    numpy_path = _on("numpy", monkeypatch, reference, simulated, dt=0.01)
    compiled = _on("numba", monkeypatch, reference, simulated, dt=0.01)
    assert compiled.lag_search is not None
    assert compiled.lag_search.method == "pyramid"
    assert compiled.lag_s == pytest.approx(-0.09)
    _assert_agree(numpy_path, compiled)


@needs_kernel
@pytest.mark.skipif(not TRIPS, reason="the i3 example data is not in this checkout")
def test_kernel_agrees_with_numpy_on_real_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """The measured i3 trips: torque against current (short, exact FFT lag search), and the
    trips' speeds laid end to end past the pyramid limit against a delayed, scaled copy."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    trips = [pd.read_parquet(path) for path in TRIPS]
    torque = trips[0]["Motor Torque [Nm]"].to_numpy(np.float64)
    current = trips[0]["Battery Current [A]"].to_numpy(np.float64) * -1.0
    pairs = [(torque, current)]
    speed = np.concatenate([t["Velocity [km/h]"].to_numpy(np.float64) for t in trips] * 8)
    assert speed.shape[0] > 1 << 18
    pairs.append((speed, np.roll(speed, 4) * 0.98 + 0.2))
    for reference, simulated in pairs:
        numpy_path = _on("numpy", monkeypatch, reference, simulated, dt=0.1)
        compiled = _on("numba", monkeypatch, reference, simulated, dt=0.1)
        _assert_agree(numpy_path, compiled)


@needs_kernel
@pytest.mark.parametrize("n", [700_001, 2_300_007])  # one thread; above KERNEL_PARALLEL_MIN
def test_kernel_is_bit_identical_across_thread_counts(
    n: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert (n > kernel.KERNEL_PARALLEL_MIN) == (n > 2_000_000)
    rng = np.random.default_rng(3)
    reference = np.cumsum(rng.normal(size=n))
    simulated = reference + rng.normal(size=n)
    one = _on("numba", monkeypatch, reference, simulated, dt=1.0, workers=1)
    two = _on("numba", monkeypatch, reference, simulated, dt=1.0, workers=2)
    assert one.as_dict() == two.as_dict()


@needs_kernel
@pytest.mark.parametrize("where", ["reference", "simulated"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_kernel_reports_non_finite_samples(
    where: str, bad: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    signals = {"reference": np.linspace(0.0, 1.0, 5000), "simulated": np.linspace(0.0, 1.1, 5000)}
    signals[where][1234] = bad
    with pytest.raises(DegenerateSignalError, match=rf"{where} signal contains NaN or inf.*1234"):
        _on("numba", monkeypatch, signals["reference"], signals["simulated"], dt=1.0)


@needs_kernel
@pytest.mark.parametrize("n", [5_000, 300_001])  # exact FFT lag search; pyramid
def test_float32_and_strided_input_score_as_their_float64_values_on_the_kernel(
    n: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(n)
    reference = (np.cumsum(rng.normal(size=n)) + 20.0).astype(np.float32)
    simulated = (np.roll(reference, 3) + rng.normal(0.0, 0.2, size=n)).astype(np.float32)
    double = _on(
        "numba", monkeypatch, reference.astype(np.float64), simulated.astype(np.float64), dt=0.01
    )
    assert _on("numba", monkeypatch, reference, simulated, dt=0.01) == double
    wide = np.repeat(reference.astype(np.float64), 2)[::2]  # a strided float64 view
    assert not wide.flags.c_contiguous
    strided = _on("numba", monkeypatch, wide, simulated.astype(np.float64), dt=0.01)
    assert strided == double


@needs_kernel
@pytest.mark.parametrize("n", [1_000_003, 2_300_017])
def test_compiled_main_pass_matches_the_numpy_sums_and_levels(n: int) -> None:
    """The compiled pass's sums agree with the numpy pass to 1e-12, its extremes and sign
    count exactly, and its pyramid levels (block means by 4, 16 and 64, and the next level of
    the lag search) bit for bit, whatever the thread count."""
    from pytest_hevval.core import characteristics as core
    from pytest_hevval.core import lag

    rng = np.random.default_rng(n)
    reference = np.cumsum(rng.normal(size=n)) + 300.0
    simulated = reference * 0.99 + rng.normal(0.2, 0.3, size=n)
    simulated[::5] = np.roll(simulated, 1)[::5]  # flat steps: derivative 0 here and there

    def levels() -> list[tuple[np.ndarray, np.ndarray]]:
        buffers = core._level_buffers(n, 0.01, 1.0)
        assert buffers is not None
        return buffers

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(kernel.KERNEL_ENV, "numpy")
        numpy_levels = levels()
        expected, _ = core._all_sums(reference, simulated, 1.0, 2, numpy_levels)
        # The main pass's third level is the lag search's next level of the second.
        np.testing.assert_array_equal(numpy_levels[2][0], lag._quarter_level(numpy_levels[1][0], 1))
        numpy_next = lag._quarter_level(numpy_levels[2][0], 2)
        for workers in (1, 2):
            patch.setenv(kernel.KERNEL_ENV, "numba")
            compiled_levels = levels()
            got, _ = core._all_sums(reference, simulated, 1.0, workers, compiled_levels)
            for (a, b), (c, d) in zip(numpy_levels, compiled_levels, strict=True):
                np.testing.assert_array_equal(a, c)
                np.testing.assert_array_equal(b, d)
            np.testing.assert_array_equal(
                lag._quarter_level(compiled_levels[2][0], workers), numpy_next
            )
            assert (got.ref_min, got.ref_max) == (reference.min(), reference.max())
            assert (got.n, got.sign_matches) == (expected.n, expected.sign_matches)
            for name in ("abs_error", "sq_error", "ref_sum", "sim_sum", "ref_sq", "sim_sq"):
                assert getattr(got, name) == pytest.approx(getattr(expected, name), rel=1e-12)
            assert got.cross == pytest.approx(expected.cross, rel=1e-12)
            assert got.error_m2 == pytest.approx(expected.error_m2, rel=1e-12)


@needs_kernel
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_a_forked_child_spreads_a_long_record_over_new_helper_threads() -> None:
    """A fork copies the helper pool without its threads; the child must make its own."""
    script = (
        "import os, numpy as np\n"
        "from pytest_hevval import signal_characteristics as sc\n"
        "r = np.random.default_rng(0).normal(size=2_200_000); s = r + 0.1\n"
        "before = sc(r, s, dt=1.0, workers=2).mae\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    os._exit(0 if sc(r, s, dt=1.0, workers=2).mae == before else 3)\n"
        "print(os.waitpid(pid, 0)[1])\n"
    )
    python_path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {**os.environ, "PYTHONPATH": python_path, "HEVVAL_KERNEL": "numba"}
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "0"


@needs_kernel
def test_the_cache_is_looked_for_where_numba_files_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from numba.core.caching import UserWideCacheLocator, _CacheLocator

    from pytest_hevval.core import _fused

    # Where this process's numba keeps it, found without asking numba.
    assert kernel.cache_folder() == Path(_fused.main_pass._cache._cache_path)
    folder = kernel._cache_folder(str(tmp_path))
    assert folder == tmp_path / _CacheLocator.get_suitable_cache_subpath(_fused.__file__)
    # A read-only install: numba falls back to its user-wide folder, and so does the look.
    monkeypatch.setattr(kernel.os, "access", lambda path, mode: False)
    kernel._cache_folder.cache_clear()
    try:
        user_wide = UserWideCacheLocator(_fused.main_pass.py_func, _fused.__file__)
        assert kernel._cache_folder(None) == Path(user_wide.get_cache_path())
    finally:
        monkeypatch.undo()
        kernel._cache_folder.cache_clear()
    names = ("main_pass", "lag_window")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(kernel, "_warm_found", set())
    monkeypatch.setattr(kernel, "_cold_seen", {})
    assert kernel.cache_folder() == folder
    assert not kernel.cache_warm(names)
    folder.mkdir(parents=True)
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    for name in names:
        (folder / f"_fused.{name}-100.{tag}.nbi").write_bytes(b"")
    monkeypatch.setattr(kernel, "_COLD_RECHECK_S", 0.0)
    assert kernel.cache_warm(names)
    assert kernel.cached_functions() == {name: name in names for name in kernel.COMPILED}


@needs_kernel
def test_each_compiled_function_has_one_signature_for_writable_and_read_only_input() -> None:
    """A record read from Parquet is read-only, one computed in memory is not: both reach the
    kernel read-only, so a warm cache never compiles again mid-run."""
    module = kernel.load_or_raise()
    kernel_cache.compile_all()  # writable inputs
    x = np.sin(np.linspace(0.0, 6.0, 512))
    y = np.cos(np.linspace(0.0, 6.0, 512))
    for a in (x, y):
        a.flags.writeable = False
    grouping = Grouping.of(np.arange(512) // 8, (64,))
    kernel.main_pass(module, x, y, 1.0, 1, None)
    kernel.main_pass(module, x, y, 1.0, 1, None, grouping.runs(x, y))
    kernel.lag_window(module, x, y, -2, 5, 0.0, 0.0, 1.0, (2, 510), 1)
    kernel.quarter_level(module, x, 1)
    kernel.grouped_sums(module, x, y, grouping.runs(x, y))
    kernel.fine_block_sums(module, x, y, 4, 8, np.empty((128, 10)))
    kernel.dtw_path(module, x[:40], y[:40], 3)
    plan = np.arange(511, dtype=np.intp)
    plan.flags.writeable = False
    kernel.interpolate(module, x, plan, np.zeros(511), np.ones(511), 1)
    for name in kernel.COMPILED:
        assert len(getattr(module, name).signatures) == 1, name


@needs_kernel
def test_hevval_kernel_compile_fills_an_empty_cache_for_every_record(tmp_path: Path) -> None:
    """``hevval kernel --compile`` in a fresh cache folder, then a run of the auto path on a
    short record read from Parquet: it takes the kernel and compiles nothing more."""
    python_path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {
        **os.environ,
        "PYTHONPATH": python_path,
        "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
        "HEVVAL_KERNEL": "auto",
    }

    def hevval(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "pytest_hevval", "kernel", *args],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )

    cold = hevval()
    assert cold.returncode == 0, cold.stderr
    assert "cache cold: the first run that would gain compiles it" in cold.stdout
    assert "missing main_pass, lag_window" in cold.stdout
    done = hevval("--compile")
    assert done.returncode == 0, done.stderr
    assert [line.split()[1] for line in done.stdout.splitlines()[: len(kernel.COMPILED)]] == list(
        kernel.COMPILED
    )
    assert "(cache warm) once a run's work pays for loading it" in done.stdout
    assert "(every function)" in done.stdout
    cached = sorted(p.name for p in (tmp_path / "numba").rglob("*.nbc"))
    # One entry per function, helpers included: a callee passed a literal (k = 0, a kind, a
    # column) would compile once per value, each a fraction of a second of a first run.
    entries = collections.Counter(name.split("-")[0] for name in cached)
    assert entries
    assert set(entries.values()) == {1}, entries
    script = (
        "import numpy as np, pyarrow as pa, pyarrow.parquet as pq\n"
        "from pytest_hevval.core import kernel\n"
        "from pytest_hevval import signal_characteristics as sc\n"
        "from pytest_hevval.core.uncertainty import block_sums_many\n"
        "t = np.arange(3000) * 0.1\n"
        "pq.write_table(pa.table({'r': np.sin(t), 's': np.sin(t - 0.2)}), 'rec.parquet')\n"
        "table = pq.read_table('rec.parquet').to_pandas()\n"
        "r, s = table['r'].to_numpy(), table['s'].to_numpy()\n"
        "kernel._load()  # as a run does once the kernel pays\n"
        "assert kernel.kernel_for(r.size, ('fine_block_sums',)) is not None\n"
        "sc(r, s, dt=0.1, max_lag_s=1.0)\n"
        "block_sums_many([(r, s), (r.copy(), s)])\n"
        "print('ok')\n"
    )
    scored = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=300,
    )
    assert scored.returncode == 0, scored.stderr
    assert sorted(p.name for p in (tmp_path / "numba").rglob("*.nbc")) == cached


def test_hevval_kernel_compile_without_numba_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from pytest_hevval import cli

    monkeypatch.setattr(kernel, "_load", lambda: None)
    assert cli.main(["kernel", "--compile"]) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith("hevval kernel: error: the compiled kernel cannot be loaded")
    assert 'pip install "pytest-hevval[fast]"' in err


@pytest.fixture
def fresh_choice(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[list[str]]:
    """The auto path's state as in a new process, numba's cache in ``tmp_path``, and a
    stand-in for the background compile's process: the commands it would have run."""
    started: list[list[str]] = []

    class Process:
        def __init__(self, command: list[str], **_: object) -> None:
            started.append(command)

    monkeypatch.setenv(kernel.KERNEL_ENV, "auto")
    monkeypatch.delenv(kernel_cache.BACKGROUND_COMPILE_ENV)
    monkeypatch.setattr(kernel, "_would_save", [0.0])
    monkeypatch.setattr(kernel_cache, "_background", {})
    monkeypatch.setattr(kernel, "_loaded", {})
    monkeypatch.setattr(kernel, "_numba_installed", lambda: True)
    monkeypatch.setattr(kernel, "cache_folder", lambda: tmp_path / "cache")
    monkeypatch.setattr(kernel_cache, "_launch", Process)
    return started


def test_auto_path_keeps_short_records_on_numpy_while_the_cache_is_cold(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    assert kernel.kernel_for(kernel.KERNEL_MIN_SAMPLES - 1) is None
    monkeypatch.setenv(kernel.KERNEL_ENV, "numpy")
    assert kernel.kernel_for(10 * kernel.KERNEL_MIN_SAMPLES) is None


def test_auto_path_takes_a_warm_kernel_only_once_loading_it_has_paid(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    """A one-trip run never pays numba's import and code loading; a long run switches once
    the numpy time the kernel would have saved reaches what loading it costs."""
    module = types.ModuleType("compiled")
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): True)
    monkeypatch.setattr(kernel, "_load", lambda: module)
    per_call = 100_000  # a 10 Hz trip of almost three hours
    saved = per_call * kernel.NUMPY_EXTRA_S["main_pass"]
    calls_to_pay = math.ceil(kernel.KERNEL_LOAD_S / saved)
    chosen = [kernel.kernel_for(per_call) for _ in range(calls_to_pay + 3)]
    assert chosen[: calls_to_pay - 1] == [None] * (calls_to_pay - 1)
    assert chosen[calls_to_pay - 1 :] == [module] * 4
    assert fresh_choice == []


def test_a_loaded_kernel_serves_short_records_at_once(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    module = types.ModuleType("compiled")
    monkeypatch.setattr(kernel, "_loaded", {"module": module})
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): True)
    assert kernel.kernel_for(10) is module
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    assert kernel.kernel_for(10) is None  # a function not cached would compile mid-run


def test_a_cold_cache_is_compiled_in_the_background_when_the_run_ends(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]], tmp_path: Path
) -> None:
    """A run that would gain goes on on numpy without a compile beside it (which would share
    its cores) and starts one compile as it ends, for the next runs."""
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    cells = int(kernel.KERNEL_LOAD_S / kernel.NUMPY_EXTRA_S["dtw_path"]) + 1
    assert kernel_cache.compile_note() is None
    assert kernel.kernel_for(cells, ("dtw_path",)) is None
    assert kernel.kernel_for(cells, ("dtw_path",)) is None
    assert fresh_choice == []
    kernel_cache.finish_run()
    kernel_cache.finish_run()
    assert len(fresh_choice) == 1
    command = fresh_choice[0]
    marker = tmp_path / "cache" / ".hevval-compiling"
    assert command[0] == sys.executable
    assert command[3] == str(marker)
    assert command[4:] == [
        *kernel_cache.FIRST_COMPILED,
        *(n for n in kernel.COMPILED if n not in kernel_cache.FIRST_COMPILED),
    ]
    assert marker.is_file()
    assert "compiled in the background" in (kernel_cache.compile_note() or "")


def test_a_process_that_lost_more_than_a_compile_to_numpy_compiles_at_once(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    """A long campaign or a cluster worker: what it needs now first."""
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    cells = kernel.KERNEL_MIN_SAMPLES - 1  # each call on numpy by its size
    calls = math.ceil(kernel.KERNEL_COMPILE_S / (cells * kernel.NUMPY_EXTRA_S["dtw_path"]))
    for _ in range(calls - 1):
        assert kernel.kernel_for(cells, ("dtw_path",)) is None
    assert fresh_choice == []
    assert kernel.kernel_for(cells, ("dtw_path",)) is None
    assert len(fresh_choice) == 1
    assert fresh_choice[0][4:] == ["dtw_path", *(n for n in kernel.COMPILED if n != "dtw_path")]


def test_a_spec_long_enough_to_pay_alone_starts_the_compile_before_it_is_scored(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    paying = math.ceil(kernel.KERNEL_LOAD_S / kernel.NUMPY_EXTRA_S["main_pass"])
    kernel_cache.expect(paying - 1)
    assert fresh_choice == []
    kernel_cache.expect(paying)
    assert len(fresh_choice) == 1
    assert fresh_choice[0][4 : 4 + len(kernel_cache.FIRST_COMPILED)] == list(
        kernel_cache.FIRST_COMPILED
    )


def test_the_engine_announces_each_spec_as_its_signals_times_its_samples(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from pytest_hevval.scoring import engine
    from pytest_hevval.spec.load import load_specs

    announced: list[int] = []
    monkeypatch.setattr(kernel_cache, "expect", announced.append)
    t = np.arange(1000) * 0.1
    pd.DataFrame({"t": t, "a": np.sin(t), "b": np.cos(t)}).to_csv(tmp_path / "ref.csv", index=False)
    pd.DataFrame({"t": t, "a": np.sin(t), "b": np.cos(t)}).to_csv(tmp_path / "sim.csv", index=False)
    (tmp_path / "s.hevval.yaml").write_text(
        "name: s\nreference: {path: ref.csv, time: t}\nmodel: {path: sim.csv, time: t}\n"
        "sets:\n  - {signal: A, ref: a, sim: a, children: [{signal: B, ref: b, sim: b}]}\n"
    )
    (spec,) = load_specs(tmp_path / "s.hevval.yaml")
    engine.evaluate_spec(spec, intervals=False)
    assert announced == [2 * 1000]


def test_the_note_names_a_compile_another_process_of_the_run_started(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]], tmp_path: Path
) -> None:
    """Under pytest-xdist the workers score and compile; the controller writes the summary."""
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    marker = tmp_path / "cache" / ".hevval-compiling"
    marker.parent.mkdir()
    assert kernel_cache.compile_note() is None
    marker.touch()
    assert "compiled in the background" in (kernel_cache.compile_note() or "")
    monkeypatch.setenv(kernel.KERNEL_ENV, "numpy")
    assert kernel_cache.compile_note() is None  # a run told to stay on numpy is not told of it
    monkeypatch.setenv(kernel.KERNEL_ENV, "auto")
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): True)
    assert kernel_cache.compile_note() is None  # it ended: nothing to say


def test_a_compile_under_way_elsewhere_is_not_started_again(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]], tmp_path: Path
) -> None:
    marker = tmp_path / "cache" / ".hevval-compiling"
    marker.parent.mkdir()
    marker.touch()
    assert kernel_cache.start_background_compile() is False
    monkeypatch.setattr(kernel_cache, "_background", {})
    old = time.time() - kernel_cache.COMPILE_LOCK_S - 1
    os.utime(marker, (old, old))  # its process died long ago
    assert kernel_cache.start_background_compile() is True
    assert len(fresh_choice) == 1


@needs_kernel
def test_a_run_ends_by_compiling_only_what_it_would_have_used(
    monkeypatch: pytest.MonkeyPatch, fresh_choice: list[list[str]]
) -> None:
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): False)
    kernel_cache.finish_run()
    assert fresh_choice == []  # a short run, which a warm kernel would not serve either
    monkeypatch.setattr(kernel, "_would_save", [kernel.KERNEL_LOAD_S])
    monkeypatch.setenv(kernel_cache.BACKGROUND_COMPILE_ENV, "0")
    kernel_cache.finish_run()
    assert fresh_choice == []
    monkeypatch.delenv(kernel_cache.BACKGROUND_COMPILE_ENV)
    monkeypatch.setenv(kernel.KERNEL_ENV, "numpy")
    kernel_cache.finish_run()
    assert fresh_choice == []
    monkeypatch.setenv(kernel.KERNEL_ENV, "auto")
    kernel_cache.finish_run()
    assert len(fresh_choice) == 1
    monkeypatch.setattr(kernel_cache, "_background", {})
    monkeypatch.setattr(kernel, "cache_warm", lambda names=(): True)
    kernel_cache.finish_run()
    assert len(fresh_choice) == 1


def test_background_compile_fills_the_cache_and_clears_its_marker(tmp_path: Path) -> None:
    """The real child process: after it, a fresh process finds every function cached."""
    python_path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {**os.environ, "PYTHONPATH": python_path, "NUMBA_CACHE_DIR": str(tmp_path / "nc")}
    env.pop(kernel_cache.BACKGROUND_COMPILE_ENV)
    script = (
        "from pytest_hevval.data import kernel_cache\n"
        "assert kernel_cache.start_background_compile(('dtw_path',))\n"
        "assert kernel_cache._background['process'].wait(timeout=280) == 0\n"
        "assert not (kernel_cache.cache_folder() / '.hevval-compiling').exists()\n"
        "print(all(kernel_cache.cached_functions().values()))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def test_auto_path_falls_back_to_numpy_when_numba_cannot_load(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(kernel.KERNEL_ENV, "auto")
    monkeypatch.setattr(kernel, "_load", lambda: None)
    assert kernel.kernel_for(10 * kernel.KERNEL_MIN_SAMPLES) is None
    got = signal_characteristics(np.arange(10.0), np.arange(10.0) + 1, dt=1.0)
    assert got.mae == pytest.approx(1.0)


def test_forcing_an_unknown_path_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(kernel.KERNEL_ENV, "gpu")
    with pytest.raises(
        HevvalError, match=r"HEVVAL_KERNEL: 'gpu' is not a kernel path.*auto, numpy or numba"
    ):
        signal_characteristics(np.arange(10.0), np.arange(10.0), dt=1.0)


def test_forcing_numba_without_it_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(kernel.KERNEL_ENV, "numba")
    monkeypatch.setattr(kernel, "_load", lambda: None)
    with pytest.raises(HevvalError, match=r"pytest-hevval\[fast\]"):
        kernel.kernel_for(100)


@pytest.mark.parametrize("path", ["numpy", "auto"])
def test_version_names_the_active_path(path: str) -> None:
    # The child must import what this process imports: this checkout, then the same path.
    python_path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {"HEVVAL_KERNEL": path, "PYTHONPATH": python_path}
    out = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "--version"],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **env},
    ).stdout
    assert out.startswith("pytest-hevval ")
    compiled = path == "auto" and _kernel_unavailable() is None
    assert ("kernel: numba" if compiled else "kernel: numpy") in out


@needs_kernel
def test_kernel_is_safe_from_several_threads_at_once() -> None:
    """The engine scores signals on several threads; each may spread a long record over the
    kernel's helper threads too. Every call gives the same result."""
    script = (
        "import numpy as np\n"
        "from concurrent.futures import ThreadPoolExecutor\n"
        "from pytest_hevval import signal_characteristics as sc\n"
        "r = np.random.default_rng(0).normal(size=2_200_000); s = r + 0.1\n"
        "with ThreadPoolExecutor(4) as pool:\n"
        "    got = set(pool.map(lambda w: sc(r, s, dt=1.0, workers=w).as_dict().__repr__(),"
        " [1, 2] * 4))\n"
        "assert len(got) == 1, got\n"
        "print('same')\n"
    )
    python_path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {**os.environ, "PYTHONPATH": python_path, "HEVVAL_KERNEL": "numba"}
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "same"


@needs_kernel
def test_compiled_group_sums_count_sign_agreement_with_ties_as_numpy_does() -> None:
    """Small integer signals have many equal neighbours: a central difference of 0 agrees only
    with another 0, on both paths."""
    rng = np.random.default_rng(0)
    for _ in range(100):
        n = int(rng.integers(3, 300))
        ref = rng.integers(0, 3, n).astype(np.float64)
        sim = rng.integers(0, 3, n).astype(np.float64)
        labels = np.sort(rng.integers(-1, 5, n))
        fast = labelled_table(ref, sim, labels, 5, compiled=True).values
        plain = labelled_table(ref, sim, labels, 5, compiled=False).values
        np.testing.assert_array_equal(fast[:, 9], plain[:, 9])


def test_the_core_writes_no_file_and_starts_no_process() -> None:
    """Filling numba's cache, its lock file and the background compile live in
    ``data/kernel_cache.py``; the core only chooses a path and dispatches. (Importing
    ``subprocess``, ``tempfile`` or ``shutil`` is forbidden to it by pyproject.toml's import
    contract; this looks for the calls that write without them.)"""
    import re

    writes = re.compile(
        r"\bopen\(|\.write_text\(|\.write_bytes\(|\.mkdir\(|\.unlink\(|\.touch\(|\.rename\("
        r"|\.replace\(\s*Path|os\.(?:remove|rename|replace|makedirs|mkdir|system|spawn\w*|fork)\b"
        r"|Popen|np\.save|\.tofile\(|\bprint\("
    )
    found = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in sorted((ROOT / "pytest_hevval" / "core").rglob("*.py"))
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if writes.search(line) and not line.lstrip().startswith("#")
    ]
    assert found == []
    # The check finds what it looks for: the lifecycle's own source writes.
    lifecycle = (ROOT / "pytest_hevval" / "data" / "kernel_cache.py").read_text(encoding="utf-8")
    assert writes.search(lifecycle)
