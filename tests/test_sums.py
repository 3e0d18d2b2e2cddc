"""λ1–λ6 from additive sums (pytest_hevval.core.sums): one function for the whole record, for
windows and region cells, and for bootstrap replicates."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pytest_hevval.core.characteristics import (
    _all_sums,
    power_of_two_scale,
    signal_characteristics,
)
from pytest_hevval.core.groups import LOCAL_CHARACTERISTICS
from pytest_hevval.core.sums import MIN_GROUP_SAMPLES, Sums, _coefficient, lambdas_from_sums
from pytest_hevval.errors import DegenerateSignalError
from tests.strategies import signal_pairs

KINDS = st.sampled_from(["xcorr", "pearson"])


def _integers(k: int, low: int, high: int, zeros: bool = True) -> st.SearchStrategy[np.ndarray]:
    """k integer-valued floats; with ``zeros`` a fair share are exactly 0 (powerless groups)."""
    value = st.integers(low, high)
    if zeros:
        value = st.one_of(st.just(0), value)
    return hnp.arrays(np.float64, k, elements=value.map(float))


@st.composite
def sum_columns(draw: st.DrawFn) -> dict[str, np.ndarray]:
    """Sums of k groups, some too small to judge and some without power.

    Integer-valued and Σref, Σsim below 2**26, so that (Σref)² is exact: Python's ``x**2``
    (C ``pow``) and numpy's square then agree, and the two forms must agree to the bit.
    """
    k = draw(st.integers(1, 12))
    n = draw(hnp.arrays(np.int64, k, elements=st.integers(0, 5_000)))
    fraction = draw(hnp.arrays(np.float64, k, elements=st.floats(0.0, 1.0)))
    return {
        "n": n,
        "abs_error": draw(_integers(k, 0, 2**40)),
        "sq_error": draw(_integers(k, 0, 2**40)),
        "error_m2": draw(_integers(k, 0, 2**40)),
        "ref_sq": draw(_integers(k, 0, 2**40)),
        "sim_sq": draw(_integers(k, 0, 2**40)),
        "cross": draw(_integers(k, -(2**40), 2**40)),
        "ref_sum": draw(_integers(k, -(2**25), 2**25)),
        "sim_sum": draw(_integers(k, -(2**25), 2**25)),
        "sign_matches": np.floor(fraction * n).astype(np.int64),
    }


def _arrays(columns: dict[str, np.ndarray], reference_range: float, kind: str) -> Any:
    """The groups' form: arrays (Σe, which λ do not read, left NaN as not taken)."""
    sums = Sums(error_sum=np.full(columns["n"].shape, math.nan), **columns)
    return lambdas_from_sums(sums, reference_range, kind)


def _numbers(columns: dict[str, np.ndarray], i: int, reference_range: float, kind: str) -> Any:
    """The whole-record form: Python numbers, as signal_characteristics passes them."""
    one = {name: column[i].item() for name, column in columns.items()}
    return lambdas_from_sums(Sums(error_sum=math.nan, **one), reference_range, kind)


def _direct(columns: dict[str, np.ndarray], reference_range: float, kind: str) -> dict[str, Any]:
    """λ1–λ6 written out plainly in numpy, independently of the package."""
    c = columns
    n = c["n"].astype(np.float64)
    with np.errstate(all="ignore"):
        mae = c["abs_error"] / n
        rms = np.maximum(np.sqrt(c["sq_error"] / n), mae)
        std = np.sqrt(c["error_m2"] / (n - 1.0))
        if kind == "pearson":
            cross = c["cross"] - c["ref_sum"] * c["sim_sum"] / n
            a = c["ref_sq"] - c["ref_sum"] ** 2 / n
            b = c["sim_sq"] - c["sim_sum"] ** 2 / n
        else:
            cross, a, b = c["cross"], c["ref_sq"], c["sim_sq"]
        r = np.clip(cross / np.sqrt(a * b), 0.0, 1.0)
        r = np.select([(a <= 1e-300) & (b <= 1e-300), (a <= 1e-300) | (b <= 1e-300)], [1.0, 0.0], r)
        errors = (mae, rms, rms - mae, std)
        values = [r, c["sign_matches"] / n]
        values += [np.clip(1.0 - e / reference_range, 0.0, 1.0) for e in errors]
    small = c["n"] < 3
    return {
        name: np.where(small, np.nan, v)
        for name, v in zip(LOCAL_CHARACTERISTICS, values, strict=True)
    }


@given(sum_columns(), st.floats(1e-3, 1e9), KINDS)
@settings(max_examples=300, deadline=None)
def test_arrays_agree_with_a_direct_numpy_computation(
    columns: dict[str, np.ndarray], reference_range: float, kind: str
) -> None:
    found = _arrays(columns, reference_range, kind).lambdas
    expected = _direct(columns, reference_range, kind)
    assert list(found) == list(LOCAL_CHARACTERISTICS)
    for name in LOCAL_CHARACTERISTICS:
        np.testing.assert_allclose(found[name], expected[name], rtol=1e-12, atol=0, err_msg=name)


@given(sum_columns(), st.floats(1e-3, 1e9), KINDS)
@settings(max_examples=300, deadline=None)
def test_python_numbers_agree_with_arrays_element_by_element(
    columns: dict[str, np.ndarray], reference_range: float, kind: str
) -> None:
    """The whole record's form (Python numbers) and the groups' form (arrays) of one sum give
    the same λ and errors; the whole record's stay Python floats."""
    arrays = _arrays(columns, reference_range, kind)
    for i in range(columns["n"].shape[0]):
        numbers = _numbers(columns, i, reference_range, kind)
        for name in LOCAL_CHARACTERISTICS:
            value, element = numbers.lambdas[name], float(arrays.lambdas[name][i])
            assert type(value) is float, name
            assert value == element or (math.isnan(value) and math.isnan(element)), name
        if columns["n"][i] >= MIN_GROUP_SAMPLES:
            for field in ("mae", "rms", "delta_e", "error_std"):
                assert getattr(numbers, field) == getattr(arrays, field)[i], field


@given(signal_pairs(), KINDS, st.sampled_from([1.0, 2.0**600, 2.0**-600]))
@settings(max_examples=150, deadline=None)
def test_the_whole_record_is_the_function_of_its_sums(
    pair: tuple[np.ndarray, np.ndarray], kind: str, magnitude: float
) -> None:
    """signal_characteristics' λ1–λ6 and errors are lambdas_from_sums of the record's own sums
    to the bit, Python floats, also when the pass rescales huge or tiny values."""
    ref, sim = pair[0] * magnitude, pair[1] * magnitude
    whole = signal_characteristics(
        ref,
        sim,
        dt=1.0,
        max_lag_s=0.0,
        correlation=kind,  # type: ignore[arg-type]
        workers=1,
    )
    peak = float(max(np.abs(ref).max(), np.abs(sim).max()))
    scale = power_of_two_scale(peak)
    running, _ = _all_sums(ref, sim, scale, 1)
    sums = running.record(scale)
    assert sums == whole.sums
    found = lambdas_from_sums(sums, whole.reference_range, kind)
    assert tuple(found.lambdas) == LOCAL_CHARACTERISTICS
    for name, expected in zip(LOCAL_CHARACTERISTICS, whole.lambdas, strict=True):
        assert type(expected) is float, name
        assert type(found.lambdas[name]) is float, name
        assert found.lambdas[name] == expected, name
    for field in ("mae", "rms", "delta_e", "error_std"):
        assert type(getattr(found, field)) is float, field
        assert getattr(found, field) == getattr(whole, field), field


@pytest.mark.parametrize(
    ("powers", "expected"), [((0.0, 0.0), 1.0), ((0.0, 4.0), 0.0), ((4.0, 1e-301), 0.0)]
)
def test_powerless_signals_in_both_forms(powers: tuple[float, float], expected: float) -> None:
    """Two powerless signals are alike (1), one against one with power share nothing (0)."""
    number = _coefficient(1.0, *powers)
    assert type(number) is float
    assert number == expected
    array = _coefficient(np.array([1.0]), np.array([powers[0]]), np.array([powers[1]]))
    assert array.tolist() == [expected]


def test_each_form_keeps_its_own_arithmetic() -> None:
    """The whole record clips −0.0 to 0.0 with min/max; the groups keep np.clip's −0.0."""
    number = _coefficient(-0.0, 2.0, 1.0)
    assert math.copysign(1.0, number) == 1.0
    array = _coefficient(np.array([-0.0]), np.array([2.0]), np.array([1.0]))
    assert math.copysign(1.0, float(array[0])) == math.copysign(1.0, float(np.clip(-0.0, 0, 1)))


def test_small_groups_are_nan_and_the_range_is_checked() -> None:
    columns = {
        "n": np.array([0, 2, 3]),
        "abs_error": np.ones(3),
        "sq_error": np.ones(3),
        "error_m2": np.ones(3),
        "ref_sq": np.ones(3),
        "sim_sq": np.ones(3),
        "cross": np.ones(3),
        "ref_sum": np.full(3, math.nan),  # not taken: λ1 is xcorr
        "sim_sum": np.full(3, math.nan),
        "sign_matches": np.array([0, 1, 3]),
    }
    found = _arrays(columns, 1.0, "xcorr").lambdas
    for name in LOCAL_CHARACTERISTICS:
        assert np.isnan(found[name][:2]).all(), name
        assert np.isfinite(found[name][2]), name
    with pytest.raises(DegenerateSignalError, match="normalising range"):
        _arrays(columns, math.inf, "xcorr")
    with pytest.raises(DegenerateSignalError, match="normalising range"):
        _numbers(columns, 2, 0.0, "xcorr")
