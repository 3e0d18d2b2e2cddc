"""Intervals end to end: every λ and Φ carries one, gates can judge a bound, and compare and
history tell a change beyond noise from noise."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval import cli
from pytest_hevval.core.registry import FUSED_CHARACTERISTICS
from pytest_hevval.core.tree import (
    TreeNode,
    emergent_replicates,
    global_metric,
    iter_nodes,
    score_tree,
)
from pytest_hevval.core.uncertainty import SHARED_BLOCK_FACTOR, block_sums, signal_intervals
from pytest_hevval.errors import SpecError
from pytest_hevval.history.compare import compare
from pytest_hevval.history.compare_fail import parse_compare_fail
from pytest_hevval.history.regressions import regressions
from pytest_hevval.history.trends import detect_steps
from pytest_hevval.results.spec_result import SpecResult
from pytest_hevval.scoring.confidence import _phi_replicates, resampled_blocks
from pytest_hevval.scoring.engine import evaluate_spec
from pytest_hevval.spec.load import parse_spec_text
from tests.recorded_runs import recorded
from tests.strategies import signal_trees
from tests.test_plugin import TREE_SPEC, write_data

pytest_plugins = ["pytester"]


def _scored(root: Path, spec_text: str = TREE_SPEC, **data: object) -> SpecResult:
    write_data(root, **data)  # type: ignore[arg-type]
    return evaluate_spec(parse_spec_text(spec_text, root / "pack.hevval.yaml")).result


def test_every_lambda_and_phi_carry_an_interval_around_their_value(tmp_path: Path) -> None:
    result = _scored(tmp_path, fault="leaf")
    assert result.phi_interval is not None
    assert result.phi_interval.low <= result.phi <= result.phi_interval.high
    assert result.phi_interval.high - result.phi_interval.low > 0
    for signal in result.signals:
        assert set(signal.intervals) == set(signal.lambdas), signal.path
        for name, value in signal.lambdas.items():
            interval = signal.intervals[name]
            assert interval.low <= value <= interval.high, (signal.path, name)
        assert signal.block_samples is not None
        assert signal.block_samples >= 1
    # The faulty leaf's error is strongly correlated: its blocks are longer than one sample.
    faulty_blocks = result.signal("E/P/I").block_samples
    assert faulty_blocks is not None
    assert faulty_blocks > 1
    # A node with children has a real λ7, and so a real interval.
    emergent = result.signal("E/P").intervals["emergent"]
    assert emergent.low < emergent.high


def test_signals_share_the_common_blocks_within_the_factor() -> None:
    common, used = resampled_blocks({"a": 40, "b": 20, "c": 19, "d": 1})
    assert common == 40
    assert used == {"a": 40, "b": 40, "c": 19, "d": 1}  # 20 · 2 ≥ 40 > 19 · 2
    assert SHARED_BLOCK_FACTOR == 2


@given(
    signal_trees(),
    st.integers(0, 2**32 - 1),
    st.sampled_from(["V1", "V2"]),
    st.sampled_from([{}, {"emergent": 0.0, "mae": 2.0}, {"theil": 3.0}]),
)
@settings(max_examples=60, deadline=None)
def test_batched_tree_replicates_are_the_tree_scored_per_replicate(
    tree: TreeNode, seed: int, variant: str, beta: dict[str, float]
) -> None:
    """λ7 and Φ of every replicate at once (per-node sums, one product per characteristic)
    are what scoring the tree afresh on each replicate's λ gives, to rounding; a node's other
    characteristics (here Theil's U) keep their point value in every replicate."""
    rng = np.random.default_rng(seed)
    paths = [node.path for node in iter_nodes([score_tree(tree, lambda p: [0.5] * 6)])]
    columns = rng.integers(0, len(paths), size=len(paths))  # some nodes share a signal
    replicated = rng.uniform(0.0, 1.0, size=(6, len(paths), 5))
    theil = {path: float(rng.uniform()) for path in paths}
    column_of = dict(zip(paths, columns.tolist(), strict=True))

    def scored(replicate: int | None) -> object:
        def base(path: tuple[str, ...]) -> dict[str, float]:
            own = replicated[:, column_of[path], 0 if replicate is None else replicate]
            return {
                **dict(zip(FUSED_CHARACTERISTICS, own.tolist(), strict=True)),
                "theil": theil[path],
            }

        return score_tree(tree, base, variant=variant)  # type: ignore[arg-type]

    point = scored(None)
    nodes = list(iter_nodes([point]))  # type: ignore[list-item]
    basis = replicated.sum(axis=0)
    found = emergent_replicates(
        [point],
        {path: basis[column_of[path]] for path in paths},
        variant=variant,  # type: ignore[list-item,arg-type]
    )
    assert set(found) == {node.path for node in nodes if node.children}
    if sum(node.alpha for node in nodes) == 0:
        return
    phi = _phi_replicates(nodes, columns, FUSED_CHARACTERISTICS, replicated, found, beta)
    for replicate in range(5):
        again = list(iter_nodes([scored(replicate)]))  # type: ignore[list-item]
        for node in again:
            if node.children:
                assert found[node.path][replicate] == pytest.approx(node.emergent, abs=1e-12)
        expected = global_metric(((n.alpha, n.lambdas) for n in again), beta)
        assert phi[replicate] == pytest.approx(expected, abs=1e-12)


def test_batched_intervals_equal_each_signal_scored_alone(tmp_path: Path, kernel_path: str) -> None:
    """The spec's signals are resampled together; each λ1–λ6 interval is still the one its
    signal gets alone (signal_intervals) at the block length reported, to rounding: its own, or
    the spec's common one within SHARED_BLOCK_FACTOR of its own. On either path, as long as the
    engine and the check take the same one."""
    write_data(tmp_path, fault="leaf")
    spec = parse_spec_text(TREE_SPEC, tmp_path / "pack.hevval.yaml")
    evaluation = evaluate_spec(spec, keep_arrays=True)
    lengths = {}
    for signal in evaluation.result.signals:
        ref, sim = evaluation.arrays[signal.path]
        lengths[signal.path] = block_sums(ref, sim).block_samples
    common = max(lengths.values())
    assert len(set(lengths.values())) > 1  # the check below sees both cases
    for signal in evaluation.result.signals:
        ref, sim = evaluation.arrays[signal.path]
        span = evaluation.characteristics[signal.path].reference_range
        blocks = block_sums(ref, sim)
        own = lengths[signal.path]
        assert signal.block_samples == (common if own * SHARED_BLOCK_FACTOR >= common else own)
        assert signal.block_samples is not None
        per_block = signal.block_samples // blocks.fine
        alone = signal_intervals(blocks, signal.lambdas, span, per_block=per_block)
        for name, interval in alone.items():
            batched = signal.intervals[name]
            assert batched.value == interval.value
            assert batched.low == pytest.approx(interval.low, abs=1e-12)
            assert batched.high == pytest.approx(interval.high, abs=1e-12)


def test_intervals_survive_json_and_are_the_same_on_every_run(
    tmp_path: Path, one_kernel_path: None
) -> None:
    # One path for both runs: another worker warming numba's cache in between would otherwise
    # move the second run to the compiled pass, equal only to rounding.
    first = _scored(tmp_path)
    again = SpecResult.from_dict(json.loads(json.dumps(first.to_dict())))
    assert again.phi_interval == first.phi_interval
    assert again.signals[0].intervals == first.signals[0].intervals
    assert _scored(tmp_path).phi_interval == first.phi_interval  # fixed seed


def _min_phi_spec(value: float, on: str) -> str:
    return TREE_SPEC.replace("min_phi: 0.5", f"min_phi: {{value: {value:.6f}, on: {on}}}")


def test_min_phi_can_judge_the_lower_or_upper_bound(tmp_path: Path) -> None:
    base = _scored(tmp_path, fault="leaf")
    assert base.phi_interval is not None
    between_low_and_phi = (base.phi_interval.low + base.phi) / 2
    between_phi_and_high = (base.phi + base.phi_interval.high) / 2
    on_lower = _scored(tmp_path, _min_phi_spec(between_low_and_phi, "lower"), fault="leaf")
    on_value = _scored(tmp_path, _min_phi_spec(between_low_and_phi, "value"), fault="leaf")
    on_upper = _scored(tmp_path, _min_phi_spec(between_phi_and_high, "upper"), fault="leaf")
    assert not on_lower.phi_passed
    assert on_value.phi_passed
    assert on_upper.phi_passed
    assert on_lower.to_dict()["min_phi_on"] == "lower"


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("{value: 1.5}", "min_phi.value"),
        ("{on: lower}", "min_phi.value"),
        ("{value: 0.9, on: middle}", "min_phi.on"),
        ("{value: 0.9, bound: lower}", "min_phi"),
    ],
)
def test_bad_min_phi_is_a_spec_error_naming_the_key(
    tmp_path: Path, value: str, message: str
) -> None:
    text = TREE_SPEC.replace("min_phi: 0.5", f"min_phi: {value}")
    with pytest.raises(SpecError) as caught:
        parse_spec_text(text, tmp_path / "pack.hevval.yaml")
    assert message in str(caught.value)
    assert "line 6" in str(caught.value) or ":6" in str(caught.value)


@pytest.mark.parametrize("workers", [[], ["-n", "2"]], ids=["serial", "xdist"])
def test_pytest_prints_phi_with_its_interval_and_the_bound_it_judges(
    pytester: pytest.Pytester, workers: list[str]
) -> None:
    base = _scored(pytester.path, fault="leaf")
    assert base.phi_interval is not None
    gate = (base.phi_interval.low + base.phi) / 2
    pytester.makefile(".hevval.yaml", pack=_min_phi_spec(gate, "lower"))
    result = pytester.runpytest("--hevval", "-rA", "--hevval-no-history", *workers)
    result.assert_outcomes(failed=4, passed=2)
    out = result.stdout.str()
    assert re.search(
        r"Φ = 0\.\d{4} \[0\.\d{4}, 0\.\d{4}\] < min_phi [0-9.]+ on the lower bound", out
    )


# -- beyond noise ------------------------------------------------------------------------------


def _spec_record(phi: float, low: float, high: float) -> dict[str, object]:
    return {
        "name": "pack",
        "spec": "pack.hevval.yaml",
        "phi": phi,
        "phi_interval": {"low": low, "high": high},
        "passed": True,
        "signals": [],
    }


@pytest.mark.parametrize(
    ("after", "rules", "regressed"),
    [
        ((0.905, 0.895, 0.915), "phi:0.001", True),  # a point drop of 0.005
        ((0.905, 0.895, 0.915), "phi:0.001+noise", False),  # but the intervals overlap
        ((0.905, 0.895, 0.915), "phi:noise", False),
        ((0.850, 0.840, 0.860), "phi:noise", True),  # disjoint: a real change
        ((0.850, 0.840, 0.860), "phi:0.1+noise", False),  # real, but within the allowed drop
    ],
)
def test_a_noise_aware_rule_fails_only_beyond_noise(
    after: tuple[float, float, float], rules: str, regressed: bool
) -> None:
    comparison = compare(
        recorded([_spec_record(*after)]), recorded([_spec_record(0.91, 0.90, 0.92)])
    )
    assert bool(regressions(comparison, parse_compare_fail(rules))) is regressed


def test_noise_aware_rule_falls_back_to_the_drop_without_intervals() -> None:
    before = _spec_record(0.91, 0.90, 0.92)
    after = _spec_record(0.905, 0.895, 0.915)
    del after["phi_interval"]
    comparison = compare(recorded([after]), recorded([before]))
    assert regressions(comparison, parse_compare_fail("phi:0.001+noise"))


@pytest.mark.parametrize("bad", ["phi:+noise", "phi:noisy", "phi:0.01+", "phi:noise+0.01"])
def test_bad_noise_rules_are_refused(bad: str) -> None:
    from pytest_hevval.history import HistoryError

    with pytest.raises(HistoryError):
        parse_compare_fail(bad)


def _run_json(root: Path, name: str, **data: object) -> Path:
    write_data(root, **data)  # type: ignore[arg-type]
    out = root / f"{name}.json"
    code = cli.main(
        ["run", str(root / "pack.hevval.yaml"), "--json", str(out), "--no-history", "--quiet"]
    )
    assert code in (0, 1)
    return out


def test_hevval_compare_passes_a_noise_only_change_and_fails_a_real_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pack.hevval.yaml").write_text(TREE_SPEC)
    before = _run_json(tmp_path, "before", seed=0)
    noise_only = _run_json(tmp_path, "noise", seed=1)  # same model, other sensor noise
    real = _run_json(tmp_path, "real", seed=0, fault="leaf")
    rule = ["--compare-fail", "lambda:noise"]
    assert cli.main(["compare", str(before), str(noise_only), *rule]) == 0
    capsys.readouterr()
    assert cli.main(["compare", str(before), str(real), *rule]) == 1
    assert "lambda:noise" in capsys.readouterr().out
    # The plain rule flags the same noise-only change as a regression: the gate would flap.
    assert cli.main(["compare", str(before), str(noise_only), "--compare-fail", "lambda:0"]) == 1


def test_history_steps_within_the_intervals_are_not_reported() -> None:
    series = [0.92] * 5 + [0.91] * 5
    assert detect_steps(series, min_size=0.001)  # without intervals: a step
    wide = [(v - 0.02, v + 0.02) for v in series]
    narrow = [(v - 0.002, v + 0.002) for v in series]
    assert detect_steps(series, min_size=0.001, intervals=wide) == []
    assert detect_steps(series, min_size=0.001, intervals=narrow)
    unknown = [None] * len(series)
    assert detect_steps(series, min_size=0.001, intervals=unknown)
