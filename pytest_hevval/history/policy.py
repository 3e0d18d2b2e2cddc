"""CI policy: whether a run is recorded, what a missing baseline means, and why a run's record
is or is not an accepted baseline.

These are decisions about the run, not about its numbers: they read the environment (is this
a CI runner?) and the options, and word what the user should do next.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ..flags import PYTEST, FrontEnd

__all__ = [
    "CI_VARIABLES",
    "BaselineDecision",
    "acceptance",
    "is_ci",
    "missing_baseline",
    "records_this_run",
]

#: Environment variables that mark a CI runner.
CI_VARIABLES = ("CI", "GITHUB_ACTIONS", "GITLAB_CI", "BUILDKITE", "JENKINS_URL", "TF_BUILD")


def is_ci(env: Mapping[str, str]) -> bool:
    """Whether the environment looks like a CI runner (``CI=true`` and common vendor variables)."""
    for name in CI_VARIABLES:
        value = env.get(name, "").strip().lower()
        if value and value not in ("0", "false", "no", "off"):
            return True
    return False


def records_this_run(*, asked: bool, refused: bool, environ: Mapping[str, str]) -> bool:
    """Whether a run writes its history record: in CI (:func:`is_ci`) or when asked, never
    when refused. A laptop's runs of half-finished work stay out of the trends and baselines
    a team reads, as pytest-benchmark saves only when asked."""
    return not refused and (asked or is_ci(environ))


@dataclass(frozen=True)
class BaselineDecision:
    """What to do when the requested baseline record does not exist.

    ``action`` is ``"fail"`` (end the session with ``message`` as the error), ``"record"``
    (this run becomes the baseline) or ``"note"`` (say so and carry on).
    """

    action: Literal["fail", "record", "note"]
    message: str

    @property
    def fails(self) -> bool:
        return self.action == "fail"


def missing_baseline(
    *,
    ci: bool,
    create_baseline: bool,
    directory: Path | str,
    wanted: str = "latest",
    recorded: bool = True,
    front_end: FrontEnd = PYTEST,
) -> BaselineDecision:
    """Decide what a missing baseline means: a failure in CI, a note locally.

    ``--hevval-create-baseline`` (and ``--hevval-accept``) turns both into "record this run
    as the baseline". The messages name the options as ``front_end`` spells them.
    """
    flag = front_end.flag
    what = {
        "latest": "no baseline record",
        "accepted": "no accepted baseline record",
    }.get(wanted, f"no record of model version {wanted!r}")
    where = f"{what} in {directory}"
    if create_baseline:
        return BaselineDecision(
            "record",
            f"{where}; this run is recorded as the baseline "
            f"({flag('create-baseline')} or {flag('accept')})",
        )
    if ci:
        return BaselineDecision(
            "fail",
            f"{where}; comparison needs one. Record one on purpose: run once with "
            f"{flag('accept')} (with the shipped GitHub workflow: run it by hand on main with "
            "'accept'), or bring the history folder to the job (the workflow's branch "
            f"hevval-history, or commit the history folder {directory})",
        )
    if not recorded:
        return BaselineDecision(
            "note",
            f"{where}; nothing to compare against yet (this run is not recorded: record one "
            f"with {flag('history')}, or compare in CI, where runs are recorded)",
        )
    return BaselineDecision(
        "note",
        f"{where}; nothing to compare against yet (the next run compares against this one)",
    )


def acceptance(
    *, compared: bool, baseline_found: bool, regressed: bool, create_baseline: bool, accept: bool
) -> str:
    """Why a run's record is, or is not, an accepted baseline (a key of ``ACCEPTANCE``).

    ``--hevval-accept`` accepts whatever the comparison found; a run that compared nothing is
    accepted, as every run was before records carried acceptance. A run that asked for a
    comparison is accepted when it found a baseline and broke no rule of compare-fail, or when
    it found none and ``--hevval-create-baseline`` made it the first.
    """
    if accept:
        return "manual"
    if not compared:
        return "not-compared"
    if not baseline_found:
        return "first-baseline" if create_baseline else "no-baseline"
    return "regressed" if regressed else "no-regression"
