"""The safe expression language of specs: derived signals (``ref:``/``sim:``) and candidates.

A spec value is either one column name or a small arithmetic expression over columns. The text
is parsed with :func:`ast.parse` in ``eval`` mode and the tree is checked against a whitelist of
node types before anything runs; evaluation walks that tree and calls NumPy directly. Nothing is
ever handed to ``eval``, ``exec`` or ``compile``, so a spec cannot reach Python objects, import
modules or touch attributes, whatever it contains.

Column names that are not Python identifiers are written in backticks
(```Battery Current [A]```). Before parsing, each backtick name is replaced by a placeholder
identifier that cannot occur in the text, and mapped back afterwards.

See ``docs/expressions.md`` for the grammar, the functions and the messages.
"""

from __future__ import annotations

import ast
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np
import numpy.typing as npt

from pytest_hevval.errors import ExpressionError, did_you_mean

__all__ = [
    "ALLOWED",
    "FUNCTIONS",
    "MAX_EXPONENT",
    "MAX_NODES",
    "MAX_SOURCE_LENGTH",
    "Expression",
    "parse_signal",
]

FloatArray = npt.NDArray[np.float64]
# Intermediate values: float arrays, 0-d for constants, or boolean arrays from comparisons.
_Value = npt.NDArray[Any]

MAX_SOURCE_LENGTH = 2_000
MAX_NODES = 200
# Only applies to number ** number; array powers are bounded by the non-finite check instead.
MAX_EXPONENT = 1_024

_PLACEHOLDER_STEM = "_hevval_column_"
# Eval mode refuses line breaks outside brackets, which YAML block scalars produce; whitespace
# never carries meaning in the language, so it is all read as spaces.
_WHITESPACE = str.maketrans({"\t": " ", "\n": " ", "\r": " ", "\f": " ", "\v": " "})


_Implementation = Callable[[Sequence[_Value], "_Context"], _Value]


class _Context:
    def __init__(self, time: FloatArray) -> None:
        self.time = time
        self._time_checked = False

    def require_increasing_time(self, function: str) -> None:
        if self._time_checked:
            return
        time = self.time
        if time.size and not np.all(np.isfinite(time)):
            bad = int(np.flatnonzero(~np.isfinite(time))[0])
            raise ExpressionError(
                f"{function}() needs finite time stamps; time[{bad}] is {time[bad]}",
                hint="clean the time column of the record before deriving signals",
            )
        steps = np.diff(time)
        if steps.size and not np.all(steps > 0):
            bad = int(np.flatnonzero(~(steps > 0))[0]) + 1
            raise ExpressionError(
                f"{function}() needs strictly increasing time; "
                f"time[{bad}] = {time[bad]:g} s does not follow time[{bad - 1}] = "
                f"{time[bad - 1]:g} s",
                hint="sort the record by time and drop duplicate time stamps",
            )
        self._time_checked = True


def _as_float(value: _Value) -> FloatArray:
    return np.asarray(value, dtype=np.float64)


def _full(value: _Value, context: _Context) -> FloatArray:
    out = np.empty(context.time.shape, dtype=np.float64)
    out[...] = _as_float(value)
    return out


def _integrate(args: Sequence[_Value], context: _Context) -> _Value:
    context.require_increasing_time("integrate")
    x = _full(args[0], context)
    if x.size == 0:
        return x
    # Imported here: scipy costs a noticeable part of start-up, and few specs integrate.
    from scipy.integrate import cumulative_trapezoid

    result: FloatArray = cumulative_trapezoid(x, context.time, initial=0.0)
    return result


def _derivative(args: Sequence[_Value], context: _Context) -> _Value:
    context.require_increasing_time("derivative")
    x = _full(args[0], context)
    if x.size < 2:
        raise ExpressionError(
            f"derivative() needs at least 2 samples; the record has {x.size}",
            hint="use a longer record",
        )
    result: FloatArray = np.gradient(x, context.time)
    return result


def _mean(args: Sequence[_Value], context: _Context) -> _Value:
    # Measured channels have dropouts; a single NaN should not blank the whole signal.
    x = _full(args[0], context)
    finite = np.isfinite(x)
    count = int(np.count_nonzero(finite))
    if count == 0:
        return np.asarray(np.nan)
    return np.asarray(float(np.sum(x[finite])) / count)


def _lag(args: Sequence[_Value], context: _Context) -> _Value:
    context.require_increasing_time("lag")
    x = _full(args[0], context)
    seconds = float(args[1])
    if x.size == 0:
        return x
    # np.interp holds the first/last value outside the record: the edge padding. On a uniform
    # grid with a whole number of steps this is an exact shift.
    result: FloatArray = np.interp(context.time - seconds, context.time, x)
    return result


def _smooth(args: Sequence[_Value], context: _Context) -> _Value:
    context.require_increasing_time("smooth")
    x = _full(args[0], context)
    window = float(args[1])
    if window <= 0:
        raise ExpressionError(
            f"smooth() needs a positive window; got {window:g} s",
            hint="write e.g. smooth(`elevation`, 5) for a 5 s centred moving average",
        )
    if x.size == 0:
        return x
    time = context.time
    finite = np.isfinite(x)
    # Subtracting an offset keeps the running sums small, so their differences stay accurate
    # on long records with a large mean (GPS elevation in metres above sea level).
    offset = float(x[finite][0]) if finite.any() else 0.0
    values = np.where(finite, x - offset, 0.0)
    sums = np.concatenate(([0.0], np.cumsum(values)))
    counts = np.concatenate(([0], np.cumsum(finite)))
    # Time stamps like 0.1·k are not exact in binary; without slack a sample exactly half a
    # window away would be in or out by rounding, making the window lopsided.
    slack = 1e-6 * float(np.median(np.diff(time))) if time.size > 1 else 0.0
    half = window / 2 + slack
    lo = np.searchsorted(time, time - half, side="left")
    hi = np.searchsorted(time, time + half, side="right")
    n = counts[hi] - counts[lo]
    with np.errstate(all="ignore"):
        mean = (sums[hi] - sums[lo]) / n + offset
    result: FloatArray = np.where(n > 0, mean, np.nan)
    return result


def _where(args: Sequence[_Value], context: _Context) -> _Value:
    del context
    result: _Value = np.where(np.asarray(args[0]).astype(bool), _as_float(args[1]), args[2])
    return _as_float(result)


def _unary(function: Callable[[FloatArray], _Value]) -> _Implementation:
    def apply(args: Sequence[_Value], context: _Context) -> _Value:
        del context
        return function(_as_float(args[0]))

    return apply


def _binary(function: Callable[[FloatArray, FloatArray], _Value]) -> _Implementation:
    def apply(args: Sequence[_Value], context: _Context) -> _Value:
        del context
        return function(_as_float(args[0]), _as_float(args[1]))

    return apply


def _clip(args: Sequence[_Value], context: _Context) -> _Value:
    del context
    x, lo, hi = (_as_float(a) for a in args)
    # np.clip with lo > hi silently returns hi; a maximum/minimum pair states the rule.
    return np.minimum(np.maximum(x, lo), hi)


@dataclass(frozen=True)
class _Function:
    params: tuple[str, ...]
    implementation: _Implementation
    formula: str
    # Parameters that must be a number written in the text (a window or delay in seconds).
    constant_params: tuple[int, ...] = ()

    def signature(self, name: str) -> str:
        return f"{name}({', '.join(self.params)})"


FUNCTIONS: dict[str, _Function] = {
    "abs": _Function(("x",), _unary(np.abs), "|x|"),
    "sqrt": _Function(("x",), _unary(np.sqrt), "√x"),
    "exp": _Function(("x",), _unary(np.exp), "eˣ"),
    "log": _Function(("x",), _unary(np.log), "natural logarithm ln x"),
    "log10": _Function(("x",), _unary(np.log10), "base-10 logarithm"),
    "sin": _Function(("x",), _unary(np.sin), "sine, x in radians"),
    "cos": _Function(("x",), _unary(np.cos), "cosine, x in radians"),
    "tan": _Function(("x",), _unary(np.tan), "tangent, x in radians"),
    "arcsin": _Function(("x",), _unary(np.arcsin), "inverse sine, in radians"),
    "arccos": _Function(("x",), _unary(np.arccos), "inverse cosine, in radians"),
    "arctan": _Function(("x",), _unary(np.arctan), "inverse tangent, in radians"),
    "arctan2": _Function(("y", "x"), _binary(np.arctan2), "angle of the point (x, y)"),
    "tanh": _Function(("x",), _unary(np.tanh), "hyperbolic tangent"),
    "sign": _Function(("x",), _unary(np.sign), "−1, 0 or 1"),
    "minimum": _Function(("a", "b"), _binary(np.minimum), "elementwise minimum"),
    "maximum": _Function(("a", "b"), _binary(np.maximum), "elementwise maximum"),
    "clip": _Function(("x", "lo", "hi"), _clip, "min(max(x, lo), hi)"),
    "where": _Function(("cond", "a", "b"), _where, "a where cond is true, else b"),
    "integrate": _Function(("x",), _integrate, "cumulative trapezoid over time, from 0"),
    "derivative": _Function(("x",), _derivative, "dx/dt by central differences"),
    "mean": _Function(("x",), _mean, "mean of the finite samples, broadcast"),
    "lag": _Function(("x", "seconds"), _lag, "x(t − seconds), edge-padded", (1,)),
    "smooth": _Function(("x", "seconds"), _smooth, "centred moving average", (1,)),
    "deg2rad": _Function(("x",), _unary(np.deg2rad), "x·π/180"),
    "rad2deg": _Function(("x",), _unary(np.rad2deg), "x·180/π"),
}

ALLOWED = (
    "allowed: + - * / **, comparisons (< <= > >= == !=), numbers, column names, "
    f"and the functions {', '.join(FUNCTIONS)}"
)

_BINARY_OPERATORS: dict[type[ast.operator], Callable[[FloatArray, FloatArray], _Value]] = {
    ast.Add: np.add,
    ast.Sub: np.subtract,
    ast.Mult: np.multiply,
    ast.Div: np.true_divide,
    ast.Pow: np.power,
}
_COMPARISONS: dict[type[ast.cmpop], Callable[[FloatArray, FloatArray], _Value]] = {
    ast.Lt: np.less,
    ast.LtE: np.less_equal,
    ast.Gt: np.greater,
    ast.GtE: np.greater_equal,
    ast.Eq: np.equal,
    ast.NotEq: np.not_equal,
}
_OPERATOR_TEXT: dict[type[ast.AST], str] = {
    ast.Mod: "%",
    ast.FloorDiv: "//",
    ast.MatMult: "@",
    ast.BitAnd: "&",
    ast.BitOr: "|",
    ast.BitXor: "^",
    ast.LShift: "<<",
    ast.RShift: ">>",
    ast.Invert: "~",
    ast.Not: "not",
    ast.Is: "is",
    ast.IsNot: "is not",
    ast.In: "in",
    ast.NotIn: "not in",
}
_CONSTRUCTS: dict[type[ast.AST], str] = {
    ast.Attribute: "attribute access (.name) is not allowed",
    ast.Subscript: "subscripts ([...]) are not allowed",
    ast.Lambda: "lambda is not allowed",
    ast.ListComp: "comprehensions are not allowed",
    ast.SetComp: "comprehensions are not allowed",
    ast.DictComp: "comprehensions are not allowed",
    ast.GeneratorExp: "comprehensions are not allowed",
    ast.JoinedStr: "f-strings are not allowed",
    ast.FormattedValue: "f-strings are not allowed",
    ast.NamedExpr: "assignment expressions (:=) are not allowed",
    ast.BoolOp: "'and'/'or' are not allowed",
    ast.IfExp: "conditional expressions (a if c else b) are not allowed",
    ast.List: "lists are not allowed",
    ast.Tuple: "tuples are not allowed",
    ast.Set: "sets are not allowed",
    ast.Dict: "dicts are not allowed",
    ast.Starred: "starred arguments are not allowed",
    ast.Slice: "slices are not allowed",
    ast.Await: "await is not allowed",
    ast.Yield: "yield is not allowed",
    ast.YieldFrom: "yield is not allowed",
}


@dataclass(frozen=True)
class Expression:
    """A parsed spec signal: one column, or an expression over columns.

    ``columns`` lists the referenced column names (without backticks) in the order they first
    appear in ``source``. ``is_column`` is true when the source is just one column name, so the
    engine can read it without evaluating anything.
    """

    source: str
    columns: tuple[str, ...]
    is_column: bool
    _tree: ast.expr | None = field(default=None, repr=False, compare=False)
    _names: Mapping[str, str] = field(default_factory=dict, repr=False, compare=False)

    def evaluate(self, columns: Mapping[str, np.ndarray], time: np.ndarray) -> np.ndarray:
        """Compute the signal on ``time``: a new float64 array of ``len(time)`` samples.

        Raises :class:`ExpressionError` for a missing or malformed column, and when the result
        is non-finite at a sample where every referenced column is finite (a division by zero,
        ``sqrt`` or ``log`` of a negative number, an overflow).
        """
        time_array = np.asarray(time, dtype=np.float64)
        if time_array.ndim != 1:
            raise ExpressionError(
                f"time must be one-dimensional; got shape {time_array.shape}",
                hint="pass the record's time column",
            )
        data = {name: self._column(name, columns, time_array) for name in self.columns}
        if self._tree is None:
            column: FloatArray = data[self.columns[0]].copy()
            return column
        context = _Context(time_array)
        with np.errstate(all="ignore"):
            value = _evaluate(self._tree, self._names, data, context)
            result = _full(value, context)
        self._check_finite(result, data, time_array)
        return result

    def _column(self, name: str, columns: Mapping[str, np.ndarray], time: FloatArray) -> FloatArray:
        if name not in columns:
            raise ExpressionError(
                f"unknown column {name!r}", hint=self._unknown_hint(name, columns)
            )
        try:
            with np.errstate(all="ignore"):
                values = np.asarray(columns[name], dtype=np.float64)
        except (TypeError, ValueError):
            raise ExpressionError(
                f"column {name!r} is not numeric",
                hint="derived signals can only use numeric columns",
            ) from None
        if values.shape != time.shape:
            raise ExpressionError(
                f"column {name!r} has shape {values.shape} but time has {time.shape}",
                hint="every column must have one value per time stamp",
            )
        return values

    def _unknown_hint(self, name: str, columns: Mapping[str, np.ndarray]) -> str:
        names = [str(c) for c in columns]
        if not self.is_column and self.source in columns:
            # "SOC-HV" parses as SOC minus HV; the user almost certainly meant the column.
            return (
                f"{self.source!r} is itself a column; quote it in backticks to use it: "
                f"`{self.source}`"
            )
        suggestion = did_you_mean(name, names)
        if suggestion:
            return suggestion
        shown = ", ".join(repr(c) for c in names[:10])
        more = f" and {len(names) - 10} more" if len(names) > 10 else ""
        return f"available columns: {shown}{more}" if names else "the record has no columns"

    def _check_finite(
        self, result: FloatArray, data: Mapping[str, FloatArray], time: FloatArray
    ) -> None:
        inputs_finite = np.ones(result.shape, dtype=bool)
        for values in data.values():
            inputs_finite &= np.isfinite(values)
        bad = ~np.isfinite(result) & inputs_finite
        count = int(np.count_nonzero(bad))
        if count == 0:
            return
        first = int(np.flatnonzero(bad)[0])
        gaps = [name for name, values in data.items() if not np.all(np.isfinite(values))]
        if gaps:
            hint = (
                f"column {gaps[0]!r} has non-finite samples, and integrate, mean, lag and "
                "smooth carry them to neighbouring samples; fill the gaps first"
            )
        else:
            example = next(iter(data), "v")
            hint = f"guard the division, e.g. maximum(`{example}`, 1), or the domain of sqrt/log"
        raise ExpressionError(
            f"expression {self.source!r} produced {count} non-finite values "
            f"(first at t={time[first]:g} s)",
            hint=hint,
        )


def parse_signal(source: str) -> Expression:
    """Parse a spec signal: a column name or an expression.

    A text without backticks is one column name when it does not parse as Python
    (``Battery Current``, ``Regenerative Braking Signal``), when it is a single identifier
    (``E_batt``), a dotted identifier (``battery.SOC``, as FMU outputs are named) or an
    identifier followed by a bracketed unit (``Time [s]``, ``Velocity [km/h]``, which Python
    would read as indexing). The column name is then the text exactly as written, surrounding
    spaces included. Anything else is an expression, and backticks always make an expression.

    Raises :class:`ExpressionError` with no file context; the caller adds file, line and key.
    """
    if not isinstance(source, str):
        raise ExpressionError(
            f"a signal must be a text; got {type(source).__name__}",
            hint="write a column name or an expression",
        )
    if not source.strip():
        raise ExpressionError(
            "a signal must name a column; got an empty text",
            hint="write a column name or an expression",
        )
    if len(source) > MAX_SOURCE_LENGTH:
        raise ExpressionError(
            f"expression is {len(source)} characters long; the limit is {MAX_SOURCE_LENGTH}",
            hint="split it into several derived signals",
        )
    quoted = "`" in source
    text, names, stem = _replace_backticks(source)
    tree = _parse(text, source, quoted)
    if tree is None:
        return Expression(source, (source,), True)
    if not quoted and _is_plain_name(tree):
        return Expression(source, (source,), True)
    if not quoted and isinstance(tree, ast.Constant) and _is_number(tree.value):
        raise ExpressionError(
            f"a signal must name a column; {source.strip()!r} is a number",
            hint="write a column name, or an expression that uses one",
        )
    count = sum(1 for node in ast.walk(tree) if isinstance(node, ast.expr))
    if count > MAX_NODES:
        raise ExpressionError(
            f"expression has {count} terms; the limit is {MAX_NODES}",
            hint="split it into several derived signals",
        )
    raw = text.encode("utf-8")
    tree = _DottedNames(raw, names, stem).visit(tree)
    _Validator(source, quoted, names).visit(tree)
    placeholders = set(names)
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and not _is_callee(node, tree):
            if node.id in placeholders:
                name = names[node.id]
            else:
                # The parser NFKC-normalises identifiers; the column is what was written.
                name = raw[node.col_offset : node.end_col_offset].decode("utf-8")
                known = names.setdefault(node.id, name)
                if known != name:
                    raise ExpressionError(
                        f"the names {known!r} and {name!r} are the same identifier",
                        hint="quote them in backticks to tell them apart",
                    )
            found.append((node.col_offset, name))
    columns = tuple(dict.fromkeys(name for _, name in sorted(found)))
    if not columns:
        raise ExpressionError(
            f"a signal must name a column; {source.strip()!r} uses none",
            hint="write a column name, or an expression that uses one",
        )
    if isinstance(tree, ast.Name):
        return Expression(source, columns, True)
    return Expression(source, columns, False, tree, dict(names))


def _replace_backticks(source: str) -> tuple[str, dict[str, str], str]:
    stem = _PLACEHOLDER_STEM
    while stem in source:
        stem += "_"
    parts: list[str] = []
    names: dict[str, str] = {}
    placeholders: dict[str, str] = {}
    position = 0
    while True:
        start = source.find("`", position)
        if start < 0:
            parts.append(source[position:])
            break
        end = source.find("`", start + 1)
        if end < 0:
            raise ExpressionError(
                f"unmatched backtick at character {start + 1}",
                hint="quote column names as `Battery Current [A]`; "
                "a column name cannot contain a backtick",
            )
        name = source[start + 1 : end]
        if not name:
            raise ExpressionError(
                f"empty column name `` at character {start + 1}",
                hint="write the column name between the backticks",
            )
        placeholder = placeholders.get(name)
        if placeholder is None:
            placeholder = f"{stem}{len(placeholders)}"
            placeholders[name] = placeholder
            names[placeholder] = name
        # Spaces keep `a`2 or 2`a` from fusing into one token with the placeholder.
        parts.append(f"{source[position:start]} {placeholder} ")
        position = end + 1
    return "".join(parts).translate(_WHITESPACE).strip(), names, stem


def _parse(text: str, source: str, quoted: bool) -> ast.expr | None:
    """Return the tree, or None when an unquoted text does not parse (it is a column name)."""
    try:
        with warnings.catch_warnings():
            # Invalid escapes or `x is 1` make the parser warn; such texts are rejected anyway.
            warnings.simplefilter("ignore")
            module = ast.parse(text, mode="eval")
    except (SyntaxError, ValueError):
        if not quoted:
            return None
        raise ExpressionError(
            f"cannot parse expression {source!r}",
            hint="check the parentheses and operators; " + ALLOWED,
        ) from None
    except (RecursionError, MemoryError):
        raise ExpressionError(
            "expression is nested too deeply",
            hint="split it into several derived signals",
        ) from None
    return module.body


def _is_plain_name(tree: ast.expr) -> bool:
    node = tree.value if isinstance(tree, ast.Subscript) else tree
    while isinstance(node, ast.Attribute):
        if node.attr.startswith("__"):
            # Never a real signal name; refuse it loudly rather than look it up.
            return False
        node = node.value
    return isinstance(node, ast.Name)


def _dotted_parts(node: ast.expr) -> list[str] | None:
    parts: list[str] = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    parts.append(node.id)
    return parts


class _DottedNames(ast.NodeTransformer):
    """Turns ``battery.SOC`` inside an expression into one column, as FMU outputs are named.

    Only chains of plain identifiers qualify; a dunder part (``x.__class__``) or a chain on a
    backtick name or a call stays an attribute access and is refused by the validator.
    """

    def __init__(self, raw: bytes, names: dict[str, str], stem: str) -> None:
        self.raw = raw
        self.names = names
        self.stem = stem

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        parts = _dotted_parts(node)
        if parts is None or parts[-1] in self.names or any(part.startswith("__") for part in parts):
            return self.generic_visit(node)
        written = self.raw[node.col_offset : node.end_col_offset].decode("utf-8")
        placeholder = f"{self.stem}{len(self.names)}"
        self.names[placeholder] = "".join(written.split())
        return ast.copy_location(ast.Name(id=placeholder, ctx=ast.Load()), node)


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_callee(node: ast.Name, tree: ast.expr) -> bool:
    return any(isinstance(n, ast.Call) and n.func is node for n in ast.walk(tree))


class _Validator:
    """Walks a tree and raises on the first node outside the language."""

    def __init__(self, source: str, quoted: bool, names: Mapping[str, str]) -> None:
        self.source = source
        self.quoted = quoted
        self.names = names

    def _reject(self, problem: str, hint: str = ALLOWED) -> ExpressionError:
        if not self.quoted and hint is ALLOWED:
            hint = (
                f"{ALLOWED}; if {self.source!r} is one column name, quote it in backticks: "
                f"`{self.source}`"
            )
        return ExpressionError(problem, hint=hint)

    def visit(self, node: ast.expr) -> None:
        if isinstance(node, ast.Constant):
            self._constant(node)
        elif isinstance(node, ast.Name):
            pass
        elif isinstance(node, ast.BinOp):
            if type(node.op) not in _BINARY_OPERATORS:
                raise self._reject(f"the operator {_OPERATOR_TEXT[type(node.op)]!r} is not allowed")
            self.visit(node.left)
            self.visit(node.right)
            if isinstance(node.op, ast.Pow):
                self._constant_power(node)
        elif isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.USub, ast.UAdd)):
                raise self._reject(f"the operator {_OPERATOR_TEXT[type(node.op)]!r} is not allowed")
            self.visit(node.operand)
        elif isinstance(node, ast.Compare):
            for op in node.ops:
                if type(op) not in _COMPARISONS:
                    raise self._reject(f"the operator {_OPERATOR_TEXT[type(op)]!r} is not allowed")
            self.visit(node.left)
            for comparator in node.comparators:
                self.visit(comparator)
        elif isinstance(node, ast.Call):
            self._call(node)
        else:
            problem = _CONSTRUCTS.get(type(node), f"{type(node).__name__} is not allowed")
            hint = ALLOWED
            if isinstance(node, ast.IfExp):
                hint = "use where(cond, a, b); " + ALLOWED
            elif isinstance(node, ast.BoolOp):
                hint = "multiply conditions for 'and', e.g. (`a` > 0) * (`b` > 0); " + ALLOWED
            raise self._reject(problem, hint)

    def _constant(self, node: ast.Constant) -> None:
        value = node.value
        if isinstance(value, bool) or value is None or value is Ellipsis:
            raise self._reject(f"{value!r} is not allowed")
        if isinstance(value, (str, bytes)):
            raise self._reject(f"strings are not allowed ({value!r})")
        if isinstance(value, complex):
            raise self._reject(f"complex numbers are not allowed ({value!r})")
        if isinstance(value, int):
            try:
                float(value)
            except OverflowError:
                raise self._reject("a number in the expression is too large", ALLOWED) from None
        elif isinstance(value, float) and not math.isfinite(value):
            raise self._reject(f"the number {value!r} is too large", ALLOWED)

    def _constant_power(self, node: ast.BinOp) -> None:
        base = _constant_value(node.left)
        exponent = _constant_value(node.right)
        if base is None or exponent is None:
            return
        if abs(exponent) > MAX_EXPONENT:
            raise ExpressionError(
                f"the exponent {exponent:g} is too large; the limit is {MAX_EXPONENT}",
                hint="write the number in scientific notation, e.g. 1e300",
            )
        try:
            math.pow(base, exponent)
        except OverflowError:
            raise ExpressionError(
                f"{base:g} ** {exponent:g} overflows",
                hint="write the number in scientific notation, e.g. 1e300",
            ) from None
        except ValueError:
            # A negative base with a fractional exponent; NaN at evaluation, reported there.
            pass

    def _call(self, node: ast.Call) -> None:
        if not isinstance(node.func, ast.Name):
            if isinstance(node.func, ast.Attribute):
                raise self._reject(_CONSTRUCTS[ast.Attribute])
            raise self._reject("only the listed functions can be called")
        name = node.func.id
        if name in self.names:
            raise self._reject(f"the column {self.names[name]!r} cannot be called")
        function = FUNCTIONS.get(name)
        if function is None:
            hint = did_you_mean(name, FUNCTIONS) or f"the functions are {', '.join(FUNCTIONS)}"
            if not self.quoted:
                hint += (
                    f"; if {self.source!r} is one column name, quote it in backticks: "
                    f"`{self.source}`"
                )
            raise ExpressionError(f"unknown function {name!r}", hint=hint)
        if node.keywords:
            keyword = node.keywords[0].arg
            shown = f"{keyword}=" if keyword else "**"
            raise ExpressionError(
                f"keyword arguments are not allowed ({shown} in {name}())",
                hint=f"pass the arguments by position: {function.signature(name)}",
            )
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise self._reject(_CONSTRUCTS[ast.Starred])
        if len(node.args) != len(function.params):
            expected = len(function.params)
            raise ExpressionError(
                f"{name}() takes {expected} argument{'s' if expected != 1 else ''}, "
                f"got {len(node.args)}",
                hint=f"write {function.signature(name)}",
            )
        for index in function.constant_params:
            value = _constant_value(node.args[index])
            if value is None or not math.isfinite(value):
                raise ExpressionError(
                    f"{name}() needs a number for {function.params[index]}",
                    hint=f"write {function.signature(name)} with a number in seconds, "
                    f"e.g. {name}(`v`, 2.5)",
                )
        for arg in node.args:
            self.visit(arg)


def _constant_value(node: ast.expr) -> float | None:
    """The value of a number written in the text (with signs and arithmetic), else None."""
    if isinstance(node, ast.Constant) and _is_number(node.value):
        try:
            return float(node.value)
        except OverflowError:
            return None
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _constant_value(node.operand)
        if operand is None:
            return None
        return -operand if isinstance(node.op, ast.USub) else operand
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY_OPERATORS:
        left = _constant_value(node.left)
        right = _constant_value(node.right)
        if left is None or right is None:
            return None
        with np.errstate(all="ignore"):
            operator = _BINARY_OPERATORS[type(node.op)]
            return float(operator(np.float64(left), np.float64(right)))
    return None


def _evaluate(
    node: ast.expr, names: Mapping[str, str], data: Mapping[str, FloatArray], context: _Context
) -> _Value:
    if isinstance(node, ast.Constant):
        assert _is_number(node.value)
        return np.asarray(float(node.value), dtype=np.float64)
    if isinstance(node, ast.Name):
        return data[names[node.id]]
    if isinstance(node, ast.BinOp):
        left = _as_float(_evaluate(node.left, names, data, context))
        right = _as_float(_evaluate(node.right, names, data, context))
        return _BINARY_OPERATORS[type(node.op)](left, right)
    if isinstance(node, ast.UnaryOp):
        operand = _as_float(_evaluate(node.operand, names, data, context))
        return np.negative(operand) if isinstance(node.op, ast.USub) else operand
    if isinstance(node, ast.Compare):
        left = _as_float(_evaluate(node.left, names, data, context))
        result: _Value | None = None
        for op, comparator in zip(node.ops, node.comparators, strict=True):
            right = _as_float(_evaluate(comparator, names, data, context))
            step = _COMPARISONS[type(op)](left, right)
            result = step if result is None else np.logical_and(result, step)
            left = right
        assert result is not None
        return result
    if isinstance(node, ast.Call):
        assert isinstance(node.func, ast.Name)
        function = FUNCTIONS[node.func.id]
        args = [_evaluate(arg, names, data, context) for arg in node.args]
        return function.implementation(args, context)
    raise AssertionError(f"unvalidated node {type(node).__name__}")
