"""The spec expression language: column-vs-expression rule, values, rejections, limits."""

from __future__ import annotations

import ast
import builtins
import math
import pickle
import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pytest_hevval.errors import ExpressionError, HevvalError
from pytest_hevval.spec.expressions import (
    ALLOWED,
    FUNCTIONS,
    MAX_NODES,
    MAX_SOURCE_LENGTH,
    Expression,
    parse_signal,
)

Array = np.ndarray

# --- fixtures ------------------------------------------------------------------------------

N = 201
DT = 0.05
TIME = np.arange(N) * DT
RNG = np.random.default_rng(20240611)
COLUMNS: dict[str, Array] = {
    "V": 20 + 5 * np.sin(0.7 * TIME),
    "E_batt": np.cumsum(RNG.normal(size=N)),
    "Battery Current [A]": 50 * np.cos(0.3 * TIME) + RNG.normal(size=N),
    "Battery Voltage [V]": 350 + RNG.normal(size=N),
    "Regenerative Braking Signal ": (np.sin(TIME) > 0.5).astype(float),
    "elevation": 300 + 2 * np.sin(0.1 * TIME) + RNG.normal(scale=0.5, size=N),
    "heading": RNG.uniform(-180, 180, size=N),
    "gap": np.where(np.arange(N) == 10, np.nan, 1.0),
}


def _trapezoid(x: Array, t: Array) -> Array:
    steps = np.diff(t) * (x[1:] + x[:-1]) / 2
    return np.concatenate(([0.0], np.cumsum(steps)))


def _gradient_uniform(x: Array, dt: float) -> Array:
    out = np.empty_like(x)
    out[1:-1] = (x[2:] - x[:-2]) / (2 * dt)
    out[0] = (x[1] - x[0]) / dt
    out[-1] = (x[-1] - x[-2]) / dt
    return out


def _shift(x: Array, steps: int) -> Array:
    """x delayed by ``steps`` samples (advanced when negative), holding the edge value."""
    index = np.clip(np.arange(x.size) - steps, 0, x.size - 1)
    return x[index]


def _moving_average(x: Array, t: Array, window: float) -> Array:
    out = np.empty_like(x)
    for i, centre in enumerate(t):
        inside = np.abs(t - centre) <= window / 2 + 1e-9
        out[i] = x[inside].mean()
    return out


def _eval(source: str, columns: dict[str, Array] | None = None, time: Array = TIME) -> Array:
    return parse_signal(source).evaluate(COLUMNS if columns is None else columns, time)


# --- column or expression -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("source", "column"),
    [
        ("Velocity [km/h]", "Velocity [km/h]"),
        ("Time [s]", "Time [s]"),
        ("Regenerative Braking Signal ", "Regenerative Braking Signal "),
        ("E_batt", "E_batt"),
        ("battery.SOC", "battery.SOC"),
        ("Accel [m/s^2]", "Accel [m/s^2]"),
        ("Temp [°C]", "Temp [°C]"),
        ("Battery Current", "Battery Current"),
        ("SOC %", "SOC %"),
        ("__import__", "__import__"),
        ("abs", "abs"),
        ("`Battery Current [A]`", "Battery Current [A]"),
        ("  `Heating Power CAN [kW]` ", "Heating Power CAN [kW]"),
        ("(`V`)", "V"),
        ("`a + b`", "a + b"),
    ],
)
def test_column_names(source: str, column: str) -> None:
    expression = parse_signal(source)
    assert expression.is_column
    assert expression.columns == (column,)
    assert expression.source == source


@pytest.mark.parametrize(
    ("source", "columns"),
    [
        ("V * 3.6", ("V",)),
        (
            "`Battery Current [A]` * `Battery Voltage [V]` / 1000",
            ("Battery Current [A]", "Battery Voltage [V]"),
        ),
        ("b + a + b + `a`", ("b", "a")),
        ("maximum(`x y`, x)", ("x y", "x")),
        ("integrate(P) / 3600", ("P",)),
        ("SOC-HV", ("SOC", "HV")),
        ("a\n  + b", ("a", "b")),
        ("`a`+`b`", ("a", "b")),
        ("vehicle.v * 3.6 + battery . SOC", ("vehicle.v", "battery.SOC")),
        ("2*`a`", ("a",)),
    ],
)
def test_expressions_list_their_columns_in_source_order(
    source: str, columns: tuple[str, ...]
) -> None:
    expression = parse_signal(source)
    assert not expression.is_column
    assert expression.columns == columns


def test_backtick_placeholder_cannot_collide_with_a_written_name() -> None:
    columns = {"_hevval_column_0": np.array([1.0, 2.0]), "x [m]": np.array([10.0, 20.0])}
    result = parse_signal("_hevval_column_0 + `x [m]`").evaluate(columns, np.array([0.0, 1.0]))
    np.testing.assert_array_equal(result, [11.0, 22.0])


def test_identifiers_are_taken_as_written() -> None:
    # Python folds "ﬁ" (one ligature character) into "fi"; the column is what the spec says.
    assert parse_signal("\ufb01 * 2").columns == ("\ufb01",)
    with pytest.raises(ExpressionError) as caught:
        parse_signal("\ufb01 + fi")
    assert str(caught.value) == (
        "the names '\ufb01' and 'fi' are the same identifier; "
        "quote them in backticks to tell them apart"
    )


def test_expression_survives_pickling() -> None:
    expression = pickle.loads(pickle.dumps(parse_signal("abs(`x [m]`) * 2")))
    result = expression.evaluate({"x [m]": np.array([-1.0, 2.0])}, np.array([0.0, 1.0]))
    np.testing.assert_array_equal(result, [2.0, 4.0])


def test_expression_is_hashable_and_comparable() -> None:
    assert parse_signal("V * 2") == parse_signal("V * 2")
    assert hash(parse_signal("V * 2")) == hash(parse_signal("V * 2"))
    assert parse_signal("V * 2") != parse_signal("V * 3")
    assert isinstance(parse_signal("V"), Expression)


# --- values ---------------------------------------------------------------------------------

C = COLUMNS
GOOD: list[tuple[str, Callable[[], Array]]] = [
    ("V", lambda: C["V"]),
    ("Regenerative Braking Signal ", lambda: C["Regenerative Braking Signal "]),
    ("V * 3.6", lambda: C["V"] * 3.6),
    ("-V + +2", lambda: 2.0 - C["V"]),
    ("V ** 2 / 2", lambda: C["V"] * C["V"] / 2),
    ("2 ** 3 * V", lambda: 8.0 * C["V"]),
    (
        "`Battery Current [A]` * `Battery Voltage [V]` / 1000",
        lambda: C["Battery Current [A]"] * C["Battery Voltage [V]"] / 1000,
    ),
    ("abs(`Battery Current [A]`)", lambda: np.abs(C["Battery Current [A]"])),
    ("sqrt(V)", lambda: C["V"] ** 0.5),
    ("exp(V / 10)", lambda: np.array([math.exp(v / 10) for v in C["V"]])),
    ("log(V)", lambda: np.array([math.log(v) for v in C["V"]])),
    ("log10(V)", lambda: np.array([math.log10(v) for v in C["V"]])),
    (
        "sin(V) + cos(V) - tan(V / 100)",
        lambda: _py(C["V"], lambda v: math.sin(v) + math.cos(v) - math.tan(v / 100)),
    ),
    ("arcsin(V / 30) + arccos(V / 30)", lambda: np.full(N, math.pi / 2)),
    ("arctan(V)", lambda: _py(C["V"], math.atan)),
    (
        "arctan2(V, E_batt)",
        lambda: np.array([math.atan2(v, e) for v, e in zip(C["V"], C["E_batt"], strict=True)]),
    ),
    ("tanh(E_batt)", lambda: _py(C["E_batt"], math.tanh)),
    ("sign(E_batt)", lambda: _py(C["E_batt"], lambda e: (e > 0) - (e < 0))),
    ("minimum(V, 21)", lambda: _py(C["V"], lambda v: min(v, 21))),
    ("maximum(V, 21)", lambda: _py(C["V"], lambda v: max(v, 21))),
    ("clip(V, 18, 22)", lambda: _py(C["V"], lambda v: min(max(v, 18), 22))),
    (
        "where(`Battery Current [A]` < 0, -`Battery Current [A]`, 0)",
        lambda: _py(C["Battery Current [A]"], lambda i: -i if i < 0 else 0.0),
    ),
    ("(V > 21) * 1", lambda: (C["V"] > 21).astype(float)),
    ("V >= 21", lambda: (C["V"] >= 21).astype(float)),
    ("18 < V <= 22", lambda: _py(C["V"], lambda v: float(18 < v <= 22))),
    ("(V == V) + (V != V)", lambda: np.ones(N)),
    ("integrate(V)", lambda: _trapezoid(C["V"], TIME)),
    ("integrate(2) + 0 * V", lambda: 2 * TIME),
    ("derivative(V)", lambda: _gradient_uniform(C["V"], DT)),
    ("mean(V)", lambda: np.full(N, sum(C["V"]) / N)),
    ("V - mean(V)", lambda: C["V"] - sum(C["V"]) / N),
    ("mean(gap)", lambda: np.ones(N)),
    ("lag(V, 0.5)", lambda: _shift(C["V"], 10)),
    ("lag(V, -0.25)", lambda: _shift(C["V"], -5)),
    ("lag(V, 2 * 0.1)", lambda: _shift(C["V"], 4)),
    ("smooth(elevation, 1)", lambda: _moving_average(C["elevation"], TIME, 1.0)),
    ("deg2rad(heading)", lambda: C["heading"] * math.pi / 180),
    ("rad2deg(deg2rad(heading))", lambda: C["heading"]),
    ("lag(derivative(V), 0.1) * 3.6", lambda: _shift(_gradient_uniform(C["V"], DT), 2) * 3.6),
]


def _py(x: Array, function: Callable[[float], float]) -> Array:
    return np.array([function(float(v)) for v in x])


@pytest.mark.parametrize(("source", "expected"), GOOD, ids=[s for s, _ in GOOD])
def test_good_expressions(source: str, expected: Callable[[], Array]) -> None:
    result = _eval(source)
    assert result.dtype == np.float64
    assert result.shape == (N,)
    np.testing.assert_allclose(result, expected(), rtol=1e-12, atol=1e-12)


def test_result_is_a_fresh_writable_array() -> None:
    result = _eval("V")
    result[0] = -1.0
    assert COLUMNS["V"][0] != -1.0
    constant = _eval("mean(V)")
    constant[0] = 0.0
    assert constant[1] != 0.0


def test_integer_and_boolean_columns_become_float() -> None:
    columns = {"n": np.array([1, 2, 3]), "flag": np.array([True, False, True])}
    result = parse_signal("n * flag").evaluate(columns, np.array([0.0, 1.0, 2.0]))
    assert result.dtype == np.float64
    np.testing.assert_array_equal(result, [1.0, 0.0, 3.0])


def test_derivative_on_a_non_uniform_grid_is_exact_for_a_parabola() -> None:
    time = np.cumsum(RNG.uniform(0.01, 0.1, size=50))
    result = parse_signal("derivative(x)").evaluate({"x": time**2}, time)
    # Central differences weighted for uneven steps are second-order: exact on quadratics.
    np.testing.assert_allclose(result[1:-1], 2 * time[1:-1], rtol=1e-9)


def test_integrate_on_a_non_uniform_grid() -> None:
    time = np.cumsum(RNG.uniform(0.01, 0.1, size=50))
    x = RNG.normal(size=50)
    result = parse_signal("integrate(x)").evaluate({"x": x}, time)
    np.testing.assert_allclose(result, _trapezoid(x, time), rtol=1e-12, atol=1e-12)


def test_smooth_edges_average_only_the_samples_inside_the_record() -> None:
    x = np.arange(10.0)
    result = parse_signal("smooth(x, 4)").evaluate({"x": x}, np.arange(10.0))
    assert result[0] == pytest.approx((0 + 1 + 2) / 3)
    assert result[5] == pytest.approx(5.0)
    assert result[9] == pytest.approx((7 + 8 + 9) / 3)


def test_smooth_skips_missing_samples() -> None:
    x = np.array([1.0, np.nan, 3.0, 5.0])
    result = parse_signal("smooth(x, 2)").evaluate({"x": x}, np.arange(4.0))
    np.testing.assert_allclose(result, [1.0, 2.0, 4.0, 4.0])


def test_empty_record() -> None:
    empty = np.array([], dtype=float)
    for source in ["x * 2", "integrate(x)", "lag(x, 1)", "smooth(x, 1)", "mean(x) + x"]:
        result = parse_signal(source).evaluate({"x": empty}, empty)
        assert result.shape == (0,)


def test_input_gaps_pass_through_without_error() -> None:
    result = _eval("gap * 2")
    assert np.isnan(result[10])
    assert np.all(result[np.arange(N) != 10] == 2.0)


# --- rejected inputs ------------------------------------------------------------------------


def _unquoted(source: str) -> str:
    return f"{ALLOWED}; if {source!r} is one column name, quote it in backticks: `{source}`"


FUNCTION_LIST = ", ".join(FUNCTIONS)

REJECTED: list[tuple[str, str]] = [
    (
        "__import__('os')",
        f"unknown function '__import__'; the functions are {FUNCTION_LIST}; if "
        "\"__import__('os')\" is one column name, quote it in backticks: `__import__('os')`",
    ),
    (
        "`x` + __import__('os').system('true')",
        f"attribute access (.name) is not allowed; {ALLOWED}",
    ),
    ("x.__class__", f"attribute access (.name) is not allowed; {_unquoted('x.__class__')}"),
    ("`x`.real", f"attribute access (.name) is not allowed; {ALLOWED}"),
    (
        "().__class__.__bases__[0].__subclasses__()",
        "attribute access (.name) is not allowed; "
        + _unquoted("().__class__.__bases__[0].__subclasses__()"),
    ),
    ("lambda: 1", f"lambda is not allowed; {_unquoted('lambda: 1')}"),
    ("`x`[0]", f"subscripts ([...]) are not allowed; {ALLOWED}"),
    ("V[0] * 2", f"subscripts ([...]) are not allowed; {_unquoted('V[0] * 2')}"),
    ("[v for v in `x`]", f"comprehensions are not allowed; {ALLOWED}"),
    (
        "clip(V, lo=1, hi=2)",
        "keyword arguments are not allowed (lo= in clip()); "
        "pass the arguments by position: clip(x, lo, hi)",
    ),
    (
        "abs(**`d`)",
        "keyword arguments are not allowed (** in abs()); pass the arguments by position: abs(x)",
    ),
    ("abs(*`x`)", f"starred arguments are not allowed; {ALLOWED}"),
    ("'abc'", f"strings are not allowed ('abc'); {_unquoted(repr('abc'))}"),
    ("`x` + 'abc'", f"strings are not allowed ('abc'); {ALLOWED}"),
    ("`x` + b'a'", f"strings are not allowed (b'a'); {ALLOWED}"),
    ("f'{V}'", f"f-strings are not allowed; {_unquoted(chr(102) + repr('{V}'))}"),
    ("(V := 1)", f"assignment expressions (:=) are not allowed; {_unquoted('(V := 1)')}"),
    ("`x` + 2j", f"complex numbers are not allowed (2j); {ALLOWED}"),
    ("`x` * True", f"True is not allowed; {ALLOWED}"),
    ("`x` + None", f"None is not allowed; {ALLOWED}"),
    ("`x` % 2", f"the operator '%' is not allowed; {ALLOWED}"),
    ("`x` // 2", f"the operator '//' is not allowed; {ALLOWED}"),
    ("`x` @ `y`", f"the operator '@' is not allowed; {ALLOWED}"),
    ("`x` & 1", f"the operator '&' is not allowed; {ALLOWED}"),
    ("~`x`", f"the operator '~' is not allowed; {ALLOWED}"),
    ("not `x`", f"the operator 'not' is not allowed; {ALLOWED}"),
    ("`x` is None", f"the operator 'is' is not allowed; {ALLOWED}"),
    ("`x` in `y`", f"the operator 'in' is not allowed; {ALLOWED}"),
    (
        "`x` and `y`",
        "'and'/'or' are not allowed; multiply conditions for 'and', e.g. (`a` > 0) * (`b` > 0); "
        + ALLOWED,
    ),
    (
        "`x` if `y` > 0 else 0",
        "conditional expressions (a if c else b) are not allowed; use where(cond, a, b); "
        + ALLOWED,
    ),
    ("(`x`, 1)", f"tuples are not allowed; {ALLOWED}"),
    ("{`x`: 1}", f"dicts are not allowed; {ALLOWED}"),
    ("`x`(1)", f"the column 'x' cannot be called; {ALLOWED}"),
    ("os.system(`x`)", f"the column 'os.system' cannot be called; {ALLOWED}"),
    ("(abs)(`x`)(1)", f"only the listed functions can be called; {ALLOWED}"),
    ("sqr(`x`)", "unknown function 'sqr'; did you mean 'sqrt'?"),
    ("eval(`x`)", f"unknown function 'eval'; the functions are {FUNCTION_LIST}"),
    ("clip(`x`)", "clip() takes 3 arguments, got 1; write clip(x, lo, hi)"),
    ("abs(`x`, 1)", "abs() takes 1 argument, got 2; write abs(x)"),
    (
        "lag(`x`, `y`)",
        "lag() needs a number for seconds; "
        "write lag(x, seconds) with a number in seconds, e.g. lag(`v`, 2.5)",
    ),
    (
        "smooth(`x`, 1e999)",
        "smooth() needs a number for seconds; "
        "write smooth(x, seconds) with a number in seconds, e.g. smooth(`v`, 2.5)",
    ),
    (
        "3",
        "a signal must name a column; '3' is a number; "
        "write a column name, or an expression that uses one",
    ),
    (
        " -2.5 ",
        "a signal must name a column; '-2.5' uses none; "
        "write a column name, or an expression that uses one",
    ),
    ("", "a signal must name a column; got an empty text; write a column name or an expression"),
    (
        "  \n",
        "a signal must name a column; got an empty text; write a column name or an expression",
    ),
    (
        "`x",
        "unmatched backtick at character 1; quote column names as `Battery Current [A]`; "
        "a column name cannot contain a backtick",
    ),
    ("a + `` ", "empty column name `` at character 5; write the column name between the backticks"),
    (
        "`a` `b`",
        f"cannot parse expression '`a` `b`'; check the parentheses and operators; {ALLOWED}",
    ),
    (
        "`x` + 10 ** 5000",
        "the exponent 5000 is too large; the limit is 1024; "
        "write the number in scientific notation, e.g. 1e300",
    ),
    (
        "`x` * 10.0 ** 400",
        "10 ** 400 overflows; write the number in scientific notation, e.g. 1e300",
    ),
    ("`x` * 1e999", f"the number inf is too large; {ALLOWED}"),
    ("`x` * " + "9" * 400, f"a number in the expression is too large; {ALLOWED}"),
    (
        "x" * (MAX_SOURCE_LENGTH + 1),
        f"expression is {MAX_SOURCE_LENGTH + 1} characters long; the limit is "
        f"{MAX_SOURCE_LENGTH}; split it into several derived signals",
    ),
    (
        "+".join(["`x`"] * 150),
        f"expression has 299 terms; the limit is {MAX_NODES}; "
        "split it into several derived signals",
    ),
]


@pytest.mark.parametrize(("source", "message"), REJECTED, ids=[s[:40] for s, _ in REJECTED])
def test_rejected(source: str, message: str) -> None:
    with pytest.raises(ExpressionError) as caught:
        parse_signal(source)
    assert str(caught.value) == message
    # The caller adds the location; the error must arrive without one.
    assert caught.value.file is None
    assert caught.value.line is None


def test_not_a_string() -> None:
    with pytest.raises(ExpressionError, match="a signal must be a text; got int"):
        parse_signal(3)  # type: ignore[arg-type]


@pytest.mark.parametrize(("name", "function"), FUNCTIONS.items())
def test_every_function_checks_its_arity(name: str, function: Any) -> None:
    arity = len(function.params)
    args = ", ".join(["`x`"] * (arity + 1))
    plural = "s" if arity != 1 else ""
    signature = f"{name}({', '.join(function.params)})"
    with pytest.raises(ExpressionError) as caught:
        parse_signal(f"{name}({args})")
    assert str(caught.value) == (
        f"{name}() takes {arity} argument{plural}, got {arity + 1}; write {signature}"
    )


def test_rejection_carries_file_context_added_by_the_caller() -> None:
    with pytest.raises(ExpressionError) as caught:
        parse_signal("sqr(`x`)")
    located = caught.value.with_context(file="spec.yaml", line=7, key="signals.power.ref")
    assert str(located).startswith("spec.yaml:7: signals.power.ref: unknown function 'sqr'")
    assert isinstance(pickle.loads(pickle.dumps(located)), ExpressionError)


# --- evaluation errors ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("source", "columns", "message"),
    [
        (
            "Velocty * 2",
            {"Velocity": np.ones(3), "V": np.ones(3)},
            "unknown column 'Velocty'; did you mean 'Velocity'?",
        ),
        (
            "Velocity [km/h]",
            {"Velocity [m/s]": np.ones(3)},
            "unknown column 'Velocity [km/h]'; did you mean 'Velocity [m/s]'?",
        ),
        (
            "zzz + 1",
            {"a": np.ones(3), "b": np.ones(3)},
            "unknown column 'zzz'; available columns: 'a', 'b'",
        ),
        ("zzz", {}, "unknown column 'zzz'; the record has no columns"),
        (
            "SOC-HV",
            {"SOC-HV": np.ones(3), "HV": np.ones(3)},
            "unknown column 'SOC'; 'SOC-HV' is itself a column; quote it in backticks to use it: "
            "`SOC-HV`",
        ),
        (
            "x * 2",
            {"x": np.ones(4)},
            "column 'x' has shape (4,) but time has (3,); every column must have one value per "
            "time stamp",
        ),
        (
            "x * 2",
            {"x": np.array(["a", "b", "c"])},
            "column 'x' is not numeric; derived signals can only use numeric columns",
        ),
        (
            "1 / x",
            {"x": np.array([1.0, 0.0, 0.0])},
            "expression '1 / x' produced 2 non-finite values (first at t=0.5 s); "
            "guard the division, e.g. maximum(`x`, 1), or the domain of sqrt/log",
        ),
        (
            "sqrt(x - 2)",
            {"x": np.array([1.0, 3.0, 4.0])},
            "expression 'sqrt(x - 2)' produced 1 non-finite values (first at t=0 s); "
            "guard the division, e.g. maximum(`x`, 1), or the domain of sqrt/log",
        ),
        (
            "integrate(x)",
            {"x": np.array([1.0, np.nan, 1.0])},
            "expression 'integrate(x)' produced 1 non-finite values (first at t=1 s); column 'x' "
            "has non-finite samples, and integrate, mean, lag and smooth carry them to "
            "neighbouring samples; fill the gaps first",
        ),
        (
            "smooth(x, -1)",
            {"x": np.ones(3)},
            "smooth() needs a positive window; got -1 s; "
            "write e.g. smooth(`elevation`, 5) for a 5 s centred moving average",
        ),
    ],
)
def test_evaluation_errors(source: str, columns: dict[str, Array], message: str) -> None:
    expression = parse_signal(source)
    with pytest.raises(ExpressionError) as caught:
        expression.evaluate(columns, np.array([0.0, 0.5, 1.0]))
    assert str(caught.value) == message


@pytest.mark.parametrize("function", ["integrate", "derivative", "lag", "smooth"])
def test_time_based_functions_need_increasing_time(function: str) -> None:
    source = f"{function}(x)" if function in {"integrate", "derivative"} else f"{function}(x, 1)"
    with pytest.raises(ExpressionError) as caught:
        parse_signal(source).evaluate({"x": np.ones(3)}, np.array([0.0, 1.0, 1.0]))
    assert str(caught.value) == (
        f"{function}() needs strictly increasing time; time[2] = 1 s does not follow "
        "time[1] = 1 s; sort the record by time and drop duplicate time stamps"
    )


def test_derivative_needs_two_samples() -> None:
    with pytest.raises(ExpressionError, match=r"derivative\(\) needs at least 2 samples"):
        parse_signal("derivative(x)").evaluate({"x": np.ones(1)}, np.zeros(1))


def test_time_must_be_one_dimensional() -> None:
    with pytest.raises(ExpressionError, match="time must be one-dimensional"):
        parse_signal("x + 1").evaluate({"x": np.ones(2)}, np.zeros((2, 1)))


def test_errors_are_catchable_as_value_error() -> None:
    with pytest.raises(ValueError, match="unknown function"):
        parse_signal("nope(`x`)")
    assert issubclass(ExpressionError, HevvalError)


# --- safety ---------------------------------------------------------------------------------


def test_never_evaluates_python(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[str] = []

    def forbidden(name: str) -> Callable[..., Any]:
        def refuse(*args: Any, **kwargs: Any) -> Any:
            calls.append(name)
            raise AssertionError(f"{name} was called")

        return refuse

    real_compile = builtins.compile

    def ast_only_compile(*args: Any, **kwargs: Any) -> Any:
        flags = kwargs.get("flags", args[3] if len(args) > 3 else 0)
        if not flags & ast.PyCF_ONLY_AST:
            calls.append("compile")
        return real_compile(*args, **kwargs)

    monkeypatch.setattr(builtins, "eval", forbidden("eval"))
    monkeypatch.setattr(builtins, "exec", forbidden("exec"))
    monkeypatch.setattr(builtins, "compile", ast_only_compile)
    for source, _ in GOOD:
        _eval(source)
    for source, _ in REJECTED:
        with pytest.raises(ExpressionError):
            parse_signal(source)
    assert calls == []


def test_injection_has_no_side_effect(tmp_path: Any) -> None:
    marker = tmp_path / "pwned"
    source = f"__import__('os').system('touch {marker}')"
    with pytest.raises(ExpressionError):
        parse_signal(source)
    with pytest.raises(ExpressionError):
        parse_signal(f"`x` + {source}")
    assert not marker.exists()


def test_deep_nesting_is_refused() -> None:
    for source in [
        "-" * 1_900 + "`x`",
        "(" * 300 + "`x`" + ")" * 300,
        "abs(" * 150 + "`x`" + ")" * 150,
    ]:
        with pytest.raises(ExpressionError):
            parse_signal(source)
    # Redundant parentheses add no terms; they stay within the limits.
    assert parse_signal("(" * 150 + "`x`" + ")" * 150).is_column


# --- properties -----------------------------------------------------------------------------


def _try_evaluate(source: str) -> None:
    try:
        expression = parse_signal(source)
    except ExpressionError:
        return
    columns = {name: np.linspace(-2.0, 2.0, 5) for name in expression.columns}
    try:
        result = expression.evaluate(columns, np.linspace(0.0, 1.0, 5))
    except ExpressionError:
        return
    assert result.shape == (5,)
    assert result.dtype == np.float64


@given(st.text())
@settings(max_examples=500)
def test_arbitrary_text_only_raises_expression_error(source: str) -> None:
    _try_evaluate(source)


@given(st.text(alphabet="`aVx_ ()+-*/%.,<>=!012e9[]'\":lambdsqrtbcwhi\n", max_size=60))
@settings(max_examples=1_000)
def test_grammar_like_text_only_raises_expression_error(source: str) -> None:
    _try_evaluate(source)


# A random tree is a pair: its source text and a function computing it from the two columns.
_Tree = tuple[str, Callable[[Array, Array], Array]]

_LEAVES: st.SearchStrategy[_Tree] = st.one_of(
    st.just(("a", lambda a, b: a)),
    st.just(("`b [x]`", lambda a, b: b)),
    st.floats(0.0, 100.0, allow_nan=False).map(
        lambda c: (repr(c), lambda a, b: np.full_like(a, c))
    ),
    st.integers(0, 9).map(lambda c: (str(c), lambda a, b: np.full_like(a, float(c)))),
)

_BINARY: dict[str, Callable[[Array, Array], Array]] = {
    "+": lambda x, y: x + y,
    "-": lambda x, y: x - y,
    "*": lambda x, y: x * y,
    "/": lambda x, y: x / y,
}


def _binary(op: str, left: _Tree, right: _Tree) -> _Tree:
    f, g = left[1], right[1]
    return (f"({left[0]} {op} {right[0]})", lambda a, b: _BINARY[op](f(a, b), g(a, b)))


def _extend(children: st.SearchStrategy[_Tree]) -> st.SearchStrategy[_Tree]:
    def negate(t: _Tree) -> _Tree:
        return (f"-({t[0]})", lambda a, b: -t[1](a, b))

    def power(t: _Tree, k: int) -> _Tree:
        return (f"({t[0]}) ** {k}", lambda a, b: t[1](a, b) ** k)

    def absolute(t: _Tree) -> _Tree:
        return (f"abs({t[0]})", lambda a, b: np.abs(t[1](a, b)))

    def choose(c: _Tree, x: _Tree, y: _Tree) -> _Tree:
        return (
            f"where({c[0]} > {x[0]}, {x[0]}, {y[0]})",
            lambda a, b: np.where(c[1](a, b) > x[1](a, b), x[1](a, b), y[1](a, b)),
        )

    return st.one_of(
        st.builds(_binary, st.sampled_from(sorted(_BINARY)), children, children),
        children.map(negate),
        st.builds(power, children, st.integers(0, 3)),
        children.map(absolute),
        st.builds(choose, children, children, children),
    )


_TREES = st.recursive(_LEAVES, _extend, max_leaves=12)
_SAMPLES = hnp.arrays(np.float64, 8, elements=st.floats(-100, 100, allow_nan=False))


@given(_TREES, _SAMPLES, _SAMPLES)
@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
def test_random_arithmetic_matches_numpy(tree: _Tree, a: Array, b: Array) -> None:
    source, reference = tree
    if not re.search(r"\ba\b(?!\()|`b \[x\]`", source):
        with pytest.raises(ExpressionError, match="must name a column"):
            parse_signal(source)
        return
    expression = parse_signal(source)
    with np.errstate(all="ignore"):
        expected = np.broadcast_to(reference(a, b), a.shape).astype(np.float64)
    time = np.arange(8.0)
    if not np.all(np.isfinite(expected)):
        with pytest.raises(ExpressionError, match="non-finite values"):
            expression.evaluate({"a": a, "b [x]": b}, time)
        return
    result = expression.evaluate({"a": a, "b [x]": b}, time)
    np.testing.assert_allclose(result, expected, rtol=1e-12, atol=0)


@given(
    st.lists(
        st.tuples(
            st.floats(0.1, 10.0),  # amplitude
            st.floats(0.01, 0.5),  # frequency in Hz
            st.floats(0.0, 2 * math.pi),  # phase
        ),
        min_size=1,
        max_size=4,
    ),
    st.floats(0.001, 0.05),
    st.integers(20, 2_000),
)
@settings(max_examples=100)
def test_integral_of_derivative_recovers_the_signal(
    components: list[tuple[float, float, float]], dt: float, n: int
) -> None:
    time = np.arange(n) * dt
    x = sum(a * np.sin(2 * math.pi * f * time + p) for a, f, p in components)
    assert isinstance(x, np.ndarray)
    result = parse_signal("integrate(derivative(x))").evaluate({"x": x}, time)
    # On a uniform grid, trapezoid-of-central-differences telescopes to
    # x[k] − x[0] + (x[k+1] − 2x[k] + x[k−1]) / 4 inside the record and is exact at both ends,
    # so the error is at most h²/4 · max|x''| ≤ h²/4 · Σ A·(2πf)². The slack on top covers
    # rounding in the cumulative sum (n terms of size ≤ max|x| each).
    curvature = sum(a * (2 * math.pi * f) ** 2 for a, f, _ in components)
    scale = sum(a for a, _, _ in components)
    tolerance = dt**2 / 4 * curvature * 1.001 + 1e-12 * n * scale
    error = np.abs(result - (x - x[0]))
    assert error.max() <= tolerance
    assert result[-1] == pytest.approx(x[-1] - x[0], abs=1e-12 * n * scale)
