"""The spec's ``diagnosis:`` block, and what its settings change in the diagnosis."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from pytest_hevval.core.diagnosis import MIN_SHARE, Candidate, diagnose_residual
from pytest_hevval.errors import SpecError
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
    assert found.responses[0].reason == "follows"
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
    assert "minor: load" in above.summary
    assert MIN_SHARE == 0.05
    with pytest.raises(SpecError):
        diagnose_residual(ref, sim, dt=DT, min_share=1.0)
