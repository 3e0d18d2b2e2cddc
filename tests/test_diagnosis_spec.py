"""The spec's ``diagnosis:`` block, what its settings change, and the shares of effects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from pytest_hevval.core.residual import MIN_SHARE, Candidate, diagnose_residual
from pytest_hevval.errors import SpecError
from pytest_hevval.report.diagnosis_text import summary
from pytest_hevval.spec.load import parse_spec_text
from pytest_hevval.spec.model import DiagnosisSpec

MINIMAL = """\
reference: ref.csv
model: {path: sim.csv}
sets:
  - signal: v
"""
DT = 0.1


def parse(text: str) -> DiagnosisSpec:
    return parse_spec_text(text, Path("/p/t.hevval.yaml")).diagnosis


def test_defaults_when_absent() -> None:
    assert parse(MINIMAL) == DiagnosisSpec(min_share=None, responses=(), causes=())


def test_keys_are_read() -> None:
    settings = parse(
        MINIMAL + 'diagnosis:\n  min_share: 0.1\n  responses: ["SoC [%]"]\n  causes: [heater_kw]\n'
    )
    assert settings == DiagnosisSpec(min_share=0.1, responses=("SoC [%]",), causes=("heater_kw",))


def test_groups_are_read() -> None:
    settings = parse(
        MINIMAL + 'diagnosis:\n  groups:\n    heater: ["Heater Current [A]", heater_kw]\n'
    )
    assert settings.groups == (("heater", ("Heater Current [A]", "heater_kw")),)


@pytest.mark.parametrize(
    ("block", "message"),
    [
        (
            "diagnosis: {min_shar: 0.1}\n",
            "/p/t.hevval.yaml:5: diagnosis.min_shar: unknown key; did you mean 'min_share'?",
        ),
        (
            "diagnosis: {min_share: 1}\n",
            "/p/t.hevval.yaml:5: diagnosis.min_share: must be below 1 (the share of the residual "
            "a relevant effect explains) (got 1.0); 0.05, the default, lists effects that remove "
            "at least 5 % of the residual",
        ),
        (
            "diagnosis: {min_share: -0.1}\n",
            "/p/t.hevval.yaml:5: diagnosis.min_share: must lie between 0 and 1 (got -0.1)",
        ),
        (
            "diagnosis:\n  responses: SoC\n",
            "/p/t.hevval.yaml:6: diagnosis.responses: must be a list of channel or candidate "
            "names (got 'SoC'); write e.g. responses: [\"Battery Temperature [°C]\"]",
        ),
        (
            "diagnosis:\n  responses: [a]\n  causes: [a]\n",
            "/p/t.hevval.yaml:7: diagnosis.causes: 'a' is declared both a response and a cause; "
            "keep it in one of the two lists",
        ),
        ("diagnosis: [a]\n", "/p/t.hevval.yaml:5: diagnosis: must be a mapping"),
        (
            "diagnosis:\n  groups:\n    heater: [a]\n",
            "/p/t.hevval.yaml:7: diagnosis.groups.heater: must be a list of at least two channel "
            "or candidate names (got 1 item); write e.g. groups: {heater: ",
        ),
        (
            "diagnosis:\n  groups:\n    heater: [a, b]\n    other: [b, c]\n",
            "/p/t.hevval.yaml:8: diagnosis.groups.other: 'b' is already in group 'heater'; a "
            "candidate measures one effect: keep it in one group",
        ),
        (
            "diagnosis:\n  responses: [a]\n  groups:\n    heater: [a, b]\n",
            "/p/t.hevval.yaml:8: diagnosis.groups.heater: 'a' is declared a response",
        ),
        (
            "diagnosis:\n  groups: [a, b]\n",
            "/p/t.hevval.yaml:6: diagnosis.groups: must be a mapping",
        ),
    ],
)
def test_bad_diagnosis_block(block: str, message: str) -> None:
    with pytest.raises(SpecError) as info:
        parse(MINIMAL + block)
    assert str(info.value).startswith(message)


def _case(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A simulated drive, a missing load, and a channel that echoes the measured signal."""
    rng = np.random.default_rng(seed)
    n = 4000
    t = np.arange(n) * DT
    sim = 20 + 15 * np.sin(t / 7) + 5 * np.sin(t / 2.3)
    load = 2 + np.clip(sps.lfilter([0.02], [1, -0.98], rng.standard_normal(n)) * 5, -2, None)
    noise = sps.lfilter([1.0], [1.0, -0.9], rng.standard_normal(n)) * 0.3
    ref = sim + load + noise
    echo = 400 - 0.8 * ref + rng.standard_normal(n) * 0.2
    return ref, sim, load, echo


def test_an_echo_is_a_response_and_declaring_it_a_cause_brings_it_back() -> None:
    ref, sim, load, echo = _case(3)
    candidates = [Candidate("load", "channel", load), Candidate("bus_v", "channel", echo)]
    found = diagnose_residual(ref, sim, dt=DT, candidates=candidates)
    assert [r.name for r in found.responses] == ["bus_v"]
    # The bus voltage is an instrument of the measured signal: an echo, never a cause.
    assert found.responses[0].reason == "echo"
    assert found.relevant[0].name == "load"
    assert all(e.name != "bus_v" for e in found.effects)
    declared = diagnose_residual(
        ref, sim, dt=DT, candidates=candidates, responses=("load",), causes=("bus_v",)
    )
    assert [(r.name, r.reason) for r in declared.responses] == [("load", "declared")]
    assert all(e.name != "load" for e in declared.effects)


def test_the_load_is_credited_with_its_mean_and_no_offset_is_left() -> None:
    ref, sim, load, _ = _case(5)
    found = diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("load", "channel", load)])
    first = found.relevant[0]
    assert first.name == "load"
    assert first.interval[0] < 1.0 < first.interval[1]
    assert first.offset_explained == pytest.approx(float(np.mean(load)), rel=0.2)
    assert [e.name for e in found.relevant] == ["load"]
    assert first.predicted["rms"] > found.lambdas["rms"]
    assert found.predicted == pytest.approx(first.predicted, abs=0.01)


def test_min_share_moves_an_effect_between_relevant_and_minor() -> None:
    ref, sim, load, _ = _case(7)
    found = diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("load", "channel", load)])
    share = found.relevant[0].share
    above = diagnose_residual(
        ref, sim, dt=DT, candidates=[Candidate("load", "channel", load)], min_share=share + 0.01
    )
    assert [e.name for e in above.minor] == ["load"]
    assert above.relevant == ()
    assert "minor: load" in summary(above)
    assert MIN_SHARE == 0.05
    with pytest.raises(SpecError):
        diagnose_residual(ref, sim, dt=DT, min_share=1.0)


def test_channels_that_measure_one_effect_are_one_finding() -> None:
    """The same load logged three ways (a current, a power in W, a power in kW with a small
    offset and its own noise): fitted side by side they split the load with opposite signs;
    grouped, the load is one finding, named by the member that explains most, with the others
    listed."""
    ref, sim, load, _ = _case(11)
    rng = np.random.default_rng(12)
    n = load.shape[0]
    current = load * 1000 / 380 + 0.05 * rng.standard_normal(n)
    watts = load * 1000 + 20 * rng.standard_normal(n)
    candidates = [
        Candidate("Heater Current [A]", "channel", current),
        Candidate("Heating Power LIN [W]", "channel", watts),
        Candidate("Heating Power CAN [kW]", "channel", load),
    ]
    found = diagnose_residual(ref, sim, dt=DT, candidates=candidates)
    (first,) = found.relevant
    assert first.name == "Heating Power CAN [kW]"
    assert set(first.members) == {"Heater Current [A]", "Heating Power LIN [W]"}
    assert first.coefficient > 0.0
    assert first.interval[0] < 1.0 < first.interval[1]
    assert first.name in summary(found)
    assert "one effect with" in summary(found)
    assert sum(e.share for e in found.effects) <= found.explained_fraction + 1.0


def test_a_declared_group_is_one_effect_whatever_the_correlation() -> None:
    ref, sim, load, _ = _case(5)
    rng = np.random.default_rng(6)
    # Two loads that together make the missing one, barely correlated with each other.
    part = np.clip(rng.standard_normal(load.shape[0]).cumsum() / 40, -1, 1)
    candidates = [Candidate("first", "channel", load - part), Candidate("second", "channel", part)]
    apart = diagnose_residual(ref, sim, dt=DT, candidates=candidates)
    assert all(not e.members for e in apart.effects)
    together = diagnose_residual(
        ref, sim, dt=DT, candidates=candidates, groups=[("first", "second")]
    )
    named = [e for e in together.effects if e.kind == "channel"]
    assert len(named) == 1
    assert {named[0].name, *named[0].members} == {"first", "second"}


def test_a_load_in_the_signals_own_unit_names_the_effect_before_a_temperature_that_follows() -> (
    None
):
    """The missing load is logged with sensor noise; a vent temperature follows the true load
    smoothly, so it explains more of the residual and correlates with the load channel. By
    the data alone the temperature names the effect; told which candidates are in the scored
    signal's dimension (a power in kW), the load channel names it, the temperature a member."""
    rng = np.random.default_rng(21)
    n = 6000
    t = np.arange(n) * DT
    sim = 20 + 15 * np.sin(t / 7) + 5 * np.sin(t / 2.3)
    true = sps.lfilter([0.01], [1, -0.99], rng.standard_normal(n)) * 8
    logged = true + true.std() * sps.lfilter([0.2], [1, -0.8], rng.standard_normal(n))
    vent = 15 + sps.lfilter([0.3], [1, -0.7], true)
    ref = sim + true + sps.lfilter([1.0], [1.0, -0.9], rng.standard_normal(n)) * 0.3
    candidates = [
        Candidate("Heater [kW]", "channel", logged),
        Candidate("Vent [°C]", "channel", vent),
    ]
    by_data = diagnose_residual(ref, sim, dt=DT, candidates=candidates)
    assert [(e.name, e.members) for e in by_data.relevant] == [("Vent [°C]", ("Heater [kW]",))]
    by_units = diagnose_residual(
        ref, sim, dt=DT, candidates=candidates, in_dimension=["Heater [kW]"]
    )
    (first,) = by_units.relevant
    assert (first.name, first.members) == ("Heater [kW]", ("Vent [°C]",))
    # Sensor noise on the regressor would pull a fine-scale coefficient towards 0; sized on
    # the slow scale, where that noise averages out, the interval holds the true 1.
    assert first.time_scale_s > DT
    assert 0.0 < first.interval[0] < 1.0 < first.interval[1]


# -- third round: physical types, echoes, the lag's edge ---------------------------------------


def test_a_temperature_that_follows_the_load_is_tested_on_what_the_load_leaves() -> None:
    """A temperature that follows a missing load through a first-order lag, with a slow drift of
    its own, competes with the load; the load is in the residual's dimension, so it is tested
    first, and the temperature only on what the load leaves."""
    ref, sim, load, _ = _case(21)
    rng = np.random.default_rng(22)
    n = load.shape[0]
    warming = sps.lfilter([0.01], [1, -0.99], load - load.mean()) * 4.0
    temperature = 20 + warming + np.linspace(0, 3, n) + 0.05 * rng.standard_normal(n)
    candidates = [
        Candidate("Cabin Temperature [°C]", "channel", temperature),
        Candidate("Heater [kW]", "channel", load + 0.3 * rng.standard_normal(n)),
    ]
    found = diagnose_residual(ref, sim, dt=DT, candidates=candidates, in_dimension=["Heater [kW]"])
    assert found.relevant[0].name == "Heater [kW]"
    assert found.relevant[0].coefficient > 0
    assert all(e.name != "Cabin Temperature [°C]" for e in found.relevant)


def test_a_state_of_charge_and_its_rate_are_echoes_never_causes() -> None:
    """The state of charge is the running sum of the measured power (logged in 0.1 % steps),
    and its rate follows the measured power: both echo the scored signal, whatever else moves
    them, while the missing load stays a cause."""
    ref, sim, load, _ = _case(5)
    soc = np.round(80 - np.cumsum(ref) * DT / 3600 / 20 * 100, 1)
    from pytest_hevval.scoring.candidates import _smoothed, derivative_window

    window = derivative_window(soc, 10, soc.shape[0])
    # Quantised: averaged over several of its steps, more than the default window.
    assert window is not None
    assert window > 10
    rate = np.gradient(_smoothed(soc, window), DT)
    candidates = [
        Candidate("SoC [%]", "channel", soc),
        Candidate("d/dt SoC [%]", "derivative", rate),
        Candidate("load", "channel", load),
    ]
    found = diagnose_residual(ref, sim, dt=DT, candidates=candidates)
    reasons = {r.name: r.reason for r in found.responses}
    assert reasons == {"SoC [%]": "echo", "d/dt SoC [%]": "echo"}, found.responses
    assert found.relevant[0].name == "load"


def test_a_channel_with_few_steps_has_no_derivative() -> None:
    from pytest_hevval.scoring.candidates import derivative_window

    n = 6000
    few = np.repeat(np.arange(10.0), n // 10)
    assert derivative_window(few, 10, n) is None
    smooth = np.sin(np.arange(n) / 50)
    assert derivative_window(smooth, 10, n) == 10


def test_a_lag_on_the_edge_of_the_search_says_so() -> None:
    from pytest_hevval.report.diagnosis_text import describe, payload
    from pytest_hevval.results.signal_diagnosis import SignalDiagnosis

    rng = np.random.default_rng(9)
    n = 4000
    t = np.arange(n) * DT
    ref = np.sin(t / 9) * 10 + sps.lfilter([1.0], [1.0, -0.95], rng.standard_normal(n))
    sim = np.roll(ref, 80)  # 8 s late; the search looks at ±3 s only
    found = diagnose_residual(ref, sim, dt=DT, max_lag_s=3.0)
    assert found.lag_at_bound
    assert found.max_lag_s == pytest.approx(3.0)
    signal = SignalDiagnosis("s", "P", "kW", False, ("P", 1), (("P", 1),), found)
    timing = next(line for line in describe(payload(signal)) if "timing:" in line)
    assert "on the edge of the ±3 s search" in timing
    assert "alignment: {max_lag_s: 6}" in timing
    within = diagnose_residual(ref, sim, dt=DT, max_lag_s=10.0)
    assert not within.lag_at_bound


def test_the_diagnosis_reads_the_references_other_channels_through_the_data_cache(
    tmp_path: Path,
) -> None:
    """A channel no spec scores reaches the diagnosis through the spec's data cache: read once
    for every signal, and let go with the file's other data once the spec is done."""
    import pandas as pd

    from pytest_hevval.results.signal_diagnosis import SignalDiagnosis
    from pytest_hevval.scoring.engine import DataCache, Evaluation
    from pytest_hevval.scoring.run import RunOptions, run_specs
    from pytest_hevval.spec.load import load_specs

    t = np.arange(0.0, 120.0, DT)
    v = 10.0 + 3.0 * np.sin(t / 5.0)
    heater = 2.0 * (np.sin(t / 17.0) > 0.0)
    pd.DataFrame({"time": t, "v": v + heater, "heater_kw": heater}).to_csv(
        tmp_path / "ref.csv", index=False
    )
    pd.DataFrame({"time": t, "v": v}).to_csv(tmp_path / "sim.csv", index=False)
    (tmp_path / "t.hevval.yaml").write_text(MINIMAL)
    specs = load_specs(tmp_path / "t.hevval.yaml")
    cache = DataCache()
    (outcome,) = run_specs(specs, RunOptions(rootdir=tmp_path, diagnose="all"), cache=cache)
    assert isinstance(outcome, Evaluation)
    found = outcome.diagnoses["v"]
    assert isinstance(found, SignalDiagnosis)
    assert found.diagnosis.relevant[0].name == "heater_kw"
    reference = str(specs[0].reference.path)
    # Once to score the spec, once for every channel the diagnosis tries.
    assert cache.reads[reference] == 2
    assert cache.held() == []
    cache.read_whole(specs[0].reference)
    assert cache.reads[reference] == 3
