"""The ``--compare-fail`` grammar: which drops of which quantities fail a run.

``parse_compare_fail`` reads the expression into :class:`Rule` values (the comparison and the
regressions it finds live in :mod:`.compare` and :mod:`.regressions`)::

    expr   := rule ("," rule)*
    rule   := field ":" amount
    field  := "phi" | "lambda" | "lag" | <characteristic> | "lambda1" … "lambda7"
    amount := drop ["+noise"] | "noise"
    drop   := number          an absolute drop, in the field's own unit
            | number "%"      a drop relative to the baseline value

``phi:0.01,lambda:0.02`` fails when any Φ drops by more than 0.01 or any λ of any signal by
more than 0.02; ``mae:1%`` fails when λ3 drops by more than 1 % of its baseline value.
``+noise`` also asks the drop to be beyond noise: the two runs' 95 % intervals do not overlap
(``phi:0.005+noise``); ``phi:noise`` fails on any drop beyond noise. Where either run has no
interval (the lag; records made before intervals existed) the drop alone decides.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..core.registry import LAMBDA_ALIASES, PAPER_CHARACTERISTICS, describe, is_registered
from ..errors import did_you_mean
from ..flags import PYTEST, FrontEnd
from ._base import HistoryError

__all__ = ["RULE_FIELDS", "Rule", "parse_compare_fail"]

#: Names accepted on the left of ``:`` and what each one checks.
RULE_FIELDS: dict[str, str] = {
    "phi": "Φ of each spec",
    "lambda": "every λ1–λ7 of every signal",
    "lag": "|lag| of every signal, in seconds (a growth is a regression)",
    **{name: f"{describe(name).symbol} of every signal" for name in PAPER_CHARACTERISTICS},
    **{alias: f"{describe(name).symbol} ({name})" for alias, name in LAMBDA_ALIASES.items()},
}
_ALIASES = LAMBDA_ALIASES
_AMOUNT = re.compile(r"^(?P<number>[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(?P<percent>%?)$")
_EXAMPLE = "phi:0.01,lambda:0.02, mae:1% or phi:0.005+noise"
_NOISE = "noise"


@dataclass(frozen=True)
class Rule:
    """One ``field:amount`` clause: how far ``field`` may get worse before the run fails."""

    field: str
    amount: float
    relative: bool
    text: str
    #: Also require the change to be beyond noise (the runs' intervals do not overlap).
    beyond_noise: bool = False

    def allowed(self, before: float) -> float:
        """The largest acceptable worsening from ``before``."""
        return abs(before) * self.amount / 100.0 if self.relative else self.amount

    def applies_to(self, field: str) -> bool:
        if self.field == "lambda":
            # Called with Φ, lag and λ fields only; every other field is a characteristic.
            return field not in ("phi", "lag")
        return self.field == field


def parse_compare_fail(expr: str, *, front_end: FrontEnd = PYTEST) -> list[Rule]:
    """Parse a compare-fail expression into rules; a bad one raises :class:`HistoryError`
    naming the option as ``front_end`` spells it."""
    option = front_end.flag("compare-fail")
    clauses = [clause.strip() for clause in expr.split(",")]
    if not expr.strip() or any(not clause for clause in clauses):
        raise HistoryError(
            f"empty rule in {expr!r}",
            key=option,
            hint=f"write comma-separated field:amount rules, e.g. {_EXAMPLE}",
        )
    rules = []
    for clause in clauses:
        name, sep, amount_text = clause.partition(":")
        name = name.strip().lower()
        if not sep:
            raise HistoryError(
                f"rule {clause!r} has no ':amount'",
                key=option,
                hint=f"write field:amount, e.g. {_EXAMPLE}",
            )
        if name not in RULE_FIELDS and not is_registered(name):
            suggestion = did_you_mean(name, RULE_FIELDS)
            raise HistoryError(
                f"unknown field {name!r} in {clause!r}" + (f"; {suggestion}" if suggestion else ""),
                key=option,
                hint="valid fields: " + ", ".join(RULE_FIELDS),
            )
        amount_text = amount_text.strip()
        beyond_noise = amount_text.lower() == _NOISE or amount_text.lower().endswith("+" + _NOISE)
        if amount_text.lower() == _NOISE:
            amount_text = "0"
        elif beyond_noise:
            amount_text = amount_text[: -len(_NOISE) - 1].strip()
        match = _AMOUNT.match(amount_text)
        if match is None:
            raise HistoryError(
                f"amount {amount_text.strip()!r} in {clause!r} is not a non-negative number "
                "or percentage",
                key=option,
                hint=f"write e.g. {_EXAMPLE}",
            )
        amount = float(match["number"])
        if not math.isfinite(amount):
            raise HistoryError(
                f"amount in {clause!r} is not finite", key=option, hint=f"write e.g. {_EXAMPLE}"
            )
        rules.append(
            Rule(
                field=_ALIASES.get(name, name),
                amount=amount,
                relative=bool(match["percent"]),
                text=clause,
                beyond_noise=beyond_noise,
            )
        )
    return rules
