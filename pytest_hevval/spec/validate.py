"""The spec's YAML validator: one place for every "key X in file F must be …" message.

:class:`Context` walks a YAML tree read with line numbers (:mod:`.yaml_lines`) and turns a bad
value into a :class:`~pytest_hevval.errors.SpecError` of the form
``file:line: key.path: problem (got …); did you mean …?``. Its converters (text, numbers, units,
choices) and the helpers below (paths, expressions, names, lists and mappings of text) serve
every section of the spec language, so each kind of value is checked, and worded, the same way
wherever a spec gives it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from ..errors import ExpressionError, SpecError, did_you_mean
from .expressions import Expression, parse_signal
from .yaml_lines import LineDict, LineList

__all__ = [
    "MAX_WEIGHT",
    "Context",
    "column_list",
    "item_name",
    "join",
    "parse_expression",
    "plain_mapping",
    "resolve",
    "string_mapping",
]

T = TypeVar("T")


class Context:
    """Location bookkeeping while walking the YAML tree."""

    def __init__(self, file: str) -> None:
        self.file = file

    def error(
        self, line: int, key: str, problem: str, *, got: Any = None, hint: str | None = None
    ) -> SpecError:
        text = problem if got is None else f"{problem} (got {_show(got)})"
        return SpecError(text, file=self.file, line=line, key=key or None, hint=hint)

    def mapping(self, value: Any, line: int, key: str) -> LineDict:
        if not isinstance(value, LineDict):
            raise self.error(line, key, "must be a mapping of keys to values", got=value)
        return value

    def check_keys(self, mapping: LineDict, allowed: tuple[str, ...], key: str) -> None:
        for name in mapping:
            if name not in allowed:
                suggestion = did_you_mean(name, allowed)
                raise self.error(
                    mapping.line_of(name),
                    join(key, name),
                    "unknown key",
                    hint=suggestion or "allowed keys: " + ", ".join(allowed),
                )

    def section(self, top: LineDict, name: str, allowed: tuple[str, ...]) -> LineDict | None:
        """The spec's section ``name`` with its keys checked, or None when the spec leaves it
        out (or leaves it empty)."""
        if name not in top or top[name] is None:
            return None
        mapping = self.mapping(top[name], top.line_of(name), name)
        self.check_keys(mapping, allowed, name)
        return mapping

    def get(
        self,
        mapping: LineDict,
        name: str,
        key: str,
        convert: Callable[[Any, int, str], T],
        default: T,
    ) -> T:
        if name not in mapping or mapping[name] is None:
            return default
        return convert(mapping[name], mapping.line_of(name), join(key, name))

    # Converters -----------------------------------------------------------------------------
    def text(self, value: Any, line: int, key: str) -> str:
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise self.error(line, key, "must be text", got=value)
        return str(value)

    def number(self, value: Any, line: int, key: str) -> float:
        if isinstance(value, str) and _EXPONENT_NUMBER.fullmatch(value.strip()):
            # YAML 1.1 reads 1e3 (no dot) as text; YAML 1.2, and every user, as a thousand.
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(line, key, "must be a number", got=value)
        try:
            number = float(value)
        except OverflowError:
            # An integer written with hundreds of digits is beyond float range.
            number = math.inf
        if not math.isfinite(number):
            raise self.error(line, key, "must be a finite number", got=value)
        return number

    def positive(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if number <= 0:
            raise self.error(line, key, "must be greater than 0", got=value)
        return number

    def non_negative(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if number < 0:
            raise self.error(line, key, "must be 0 or more", got=value)
        return number

    def weight(self, value: Any, line: int, key: str) -> float:
        """A weight (β, α): only ratios count, so bounded far below where Σ α·β overflows."""
        number = self.non_negative(value, line, key)
        if number > MAX_WEIGHT:
            raise self.error(
                line,
                key,
                f"must be at most {MAX_WEIGHT:g} (only the ratios of weights count)",
                got=value,
            )
        return number

    def unit_text(self, value: Any, line: int, key: str) -> str:
        """A unit as pint reads it, bounded before pint sees it: pint evaluates powers with
        Python's integers, so ``m * 9**9**9`` would compute for ever."""
        text = self.text(value, line, key)
        problem = None
        if len(text) > _MAX_UNIT_TEXT:
            problem = f"is longer than {_MAX_UNIT_TEXT} characters"
        elif not text.isprintable():
            problem = "must be one line of printable characters"
        elif _CHAINED_POWER.search(text) or any(
            abs(float(power)) > _MAX_UNIT_POWER for power in _POWER.findall(text)
        ):
            problem = f"may raise a unit only to a power of at most {_MAX_UNIT_POWER}, once"
        elif text.count("(") != text.count(")"):
            problem = "has unbalanced parentheses"
        if problem is not None:
            raise self.error(line, key, problem, got=text)
        return text

    def unit_interval(self, value: Any, line: int, key: str) -> float:
        number = self.number(value, line, key)
        if not 0.0 <= number <= 1.0:
            raise self.error(line, key, "must lie between 0 and 1", got=value)
        return number

    def flag(self, value: Any, line: int, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(line, key, "must be true or false", got=value)
        return value

    def choice(self, options: tuple[str, ...]) -> Callable[[Any, int, str], str]:
        def convert(value: Any, line: int, key: str) -> str:
            text = self.text(value, line, key)
            if text not in options:
                raise self.error(
                    line,
                    key,
                    "must be one of " + ", ".join(options),
                    got=value,
                    hint=did_you_mean(text, options) or None,
                )
            return text

        return convert


def _show(value: Any) -> str:
    if isinstance(value, LineDict):
        return "a mapping"
    if isinstance(value, LineList):
        return "a list"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: The largest weight β or α: weights are relative, and Σ α·β must stay far from overflow.
MAX_WEIGHT = 1e6
#: A number in exponent form without a dot, which YAML 1.1 reads as text (``1e3``).
_EXPONENT_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)[eE][+-]?\d+")
#: Bounds on a unit's text (``ref_unit``, ``sim_unit``, ``unit``).
_MAX_UNIT_TEXT = 64
_MAX_UNIT_POWER = 12
_POWER = re.compile(r"(?:\*\*|\^)\s*\(?\s*([+-]?\d+(?:\.\d*)?)")
_CHAINED_POWER = re.compile(r"(?:\*\*|\^)\s*\(?\s*[+-]?[\d.]+\s*\)?\s*(?:\*\*|\^)")


def join(key: str, name: str | int) -> str:
    """``key.name`` for a mapping's key, ``key[i]`` for a list's item."""
    if isinstance(name, int):
        return f"{key}[{name}]"
    return f"{key}.{name}" if key else name


def column_list(context: Context, mapping: LineDict, name: str, key: str) -> tuple[str, ...]:
    """``mapping[name]``: a list of column names."""
    raw = mapping[name]
    where = join(key, name)
    if not isinstance(raw, LineList):
        raise context.error(mapping.line_of(name), where, "must be a list of column names", got=raw)
    return tuple(context.text(v, raw.line_of(i), join(where, i)) for i, v in enumerate(raw))


def resolve(context: Context, base: Path, raw: str, line: int, key: str) -> str:
    """A path from the spec, absolute, resolved from the spec's folder ``base``."""
    if "\x00" in raw:
        raise context.error(line, key, "a file path cannot contain a NUL character", got=raw)
    try:
        # strict=True on 3.13+ reports a symlink loop as OSError (non-strict resolve no longer
        # raises there); earlier versions raise RuntimeError even when not strict. A missing
        # file is not an error here: the reader reports it with what to do.
        return str((base / raw).resolve(strict=True))
    except FileNotFoundError:
        return str((base / raw).resolve())
    except (OSError, RuntimeError) as exc:
        raise context.error(line, key, f"cannot resolve the path ({exc})", got=raw) from None


def plain_mapping(context: Context) -> Callable[[Any, int, str], dict[str, Any]]:
    """A converter for :meth:`Context.get` that takes any mapping, as a plain dict."""

    def convert(value: Any, line: int, key: str) -> dict[str, Any]:
        return dict(context.mapping(value, line, key))

    return convert


def string_mapping(context: Context, value: Any, line: int, key: str) -> dict[str, str]:
    """A mapping of names to text, such as an FMU's ``inputs`` or ``outputs``."""
    mapping = context.mapping(value, line, key)
    return {
        str(k): context.text(v, mapping.line_of(k), join(key, str(k))) for k, v in mapping.items()
    }


def parse_expression(context: Context, value: Any, line: int, key: str) -> Expression:
    """A signal expression (:mod:`.expressions`); its problems become a :class:`SpecError`."""
    text = context.text(value, line, key)
    try:
        return parse_signal(text)
    except ExpressionError as exc:
        raise SpecError(
            f"{exc.problem} (got {text!r})", file=context.file, line=line, key=key, hint=exc.hint
        ) from None


def item_name(context: Context, name: str, line: int, key: str) -> str:
    """A name that becomes part of a test item's id: one printable line without '/' or '::'
    (a line break in it could print a forged line, such as a PASSED, into a CI log)."""
    if not name.strip() or "/" in name or "::" in name or not name.isprintable():
        raise context.error(
            line,
            key,
            "must be a non-empty name on one line, of printable characters, without '/' or '::'",
            got=name,
        )
    return name
