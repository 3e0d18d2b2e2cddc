"""One error root for everything the user can fix.

Every error carries structured fields (file, line, key, column) so that pytest reports,
the CLI and JSON output can all show the same thing. The classes are also ``ValueError``
(or ``ImportError``) so that callers who do not know this package still catch them, and they
pickle cleanly so that they cross process boundaries (xdist workers, Dask).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any

__all__ = [
    "CharacteristicError",
    "DataError",
    "DegenerateSignalError",
    "ExpressionError",
    "HevvalError",
    "MissingExtraError",
    "SpecError",
    "did_you_mean",
]


#: The longest name or value an error message quotes: a column named by a megabyte of NUL
#: bytes must not become a megabyte of message.
MESSAGE_PART = 200


def _bounded(text: str, limit: int = MESSAGE_PART) -> str:
    if len(text) <= limit:
        return text
    return f"{text[:limit]}… ({len(text) - limit:,} more characters)"


class HevvalError(Exception):
    """Root of every error pytest-hevval raises on purpose.

    ``str(error)`` is the complete, user-facing message: location first, then the problem,
    then what to do next.
    """

    def __init__(
        self,
        problem: str,
        *,
        file: str | None = None,
        line: int | None = None,
        key: str | None = None,
        column: str | None = None,
        hint: str | None = None,
    ) -> None:
        self.problem = problem
        self.file = file
        self.line = line
        self.key = key
        self.column = column
        self.hint = hint
        super().__init__(self._render())

    def _render(self) -> str:
        location = ""
        if self.file is not None:
            location = self.file if self.line is None else f"{self.file}:{self.line}"
        parts = []
        if location:
            parts.append(f"{location}: ")
        if self.key:
            parts.append(f"{self.key}: ")
        if self.column is not None:
            parts.append(f"column {_bounded(repr(self.column))}: ")
        parts.append(_bounded(self.problem, 4 * MESSAGE_PART))
        if self.hint:
            parts.append(f"; {_bounded(self.hint, 4 * MESSAGE_PART)}")
        return "".join(parts)

    def with_context(self, **fields: Any) -> HevvalError:
        """Return a copy with missing location fields filled in (existing ones win)."""
        values: dict[str, Any] = {
            "file": self.file,
            "line": self.line,
            "key": self.key,
            "column": self.column,
            "hint": self.hint,
        }
        for name, value in fields.items():
            if values.get(name) is None:
                values[name] = value
        return type(self)(self.problem, **values)

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            _rebuild,
            (
                type(self),
                self.problem,
                self.file,
                self.line,
                self.key,
                self.column,
                self.hint,
            ),
        )


def _rebuild(
    cls: type[HevvalError],
    problem: str,
    file: str | None,
    line: int | None,
    key: str | None,
    column: str | None,
    hint: str | None,
) -> HevvalError:
    return cls(problem, file=file, line=line, key=key, column=column, hint=hint)


class SpecError(HevvalError, ValueError):
    """A validation spec is malformed: wrong key, wrong type, impossible value."""


class DataError(HevvalError, ValueError):
    """Measured or simulated data cannot be read or aligned."""


class ExpressionError(HevvalError, ValueError):
    """A signal or candidate expression is not allowed or cannot be evaluated."""


class DegenerateSignalError(HevvalError, ValueError):
    """A signal pair on which the characteristics are undefined (constant reference, NaN…)."""


class CharacteristicError(HevvalError, ValueError):
    """A characteristic is defined badly (name clash, bad field) or computed a bad value."""


class OutputError(HevvalError, OSError):
    """An output (JSON, a report, a history record, a sidecar, a plot) could not be written;
    nothing was half-written."""


class MissingExtraError(HevvalError, ImportError):
    """An optional dependency is needed for this input; the message names the pip command."""

    @classmethod
    def for_extra(cls, feature: str, extra: str, module: str) -> MissingExtraError:
        return cls(
            f"{feature} needs the optional package {module!r}, which is not installed",
            hint=f"install it with: pip install 'pytest-hevval[{extra}]'",
        )


def did_you_mean(word: str, choices: Iterable[str], *, n: int = 3) -> str:
    """Return ``"; did you mean 'x'?"``-style text, or an empty string when nothing is close."""
    pool = [str(c) for c in choices]
    close = difflib.get_close_matches(word, pool, n=n, cutoff=0.6)
    if not close:
        lowered = {c.lower(): c for c in pool}
        close = [lowered[c] for c in difflib.get_close_matches(word.lower(), list(lowered), n=n)]
    if not close:
        return ""
    quoted = ", ".join(repr(c) for c in close)
    return f"did you mean {quoted}?"
