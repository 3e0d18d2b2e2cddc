"""Defaults shared by the pytest options and the ``hevval`` command line, each defined once,
and the one rule every layer reads a spec's key by."""

from __future__ import annotations

__all__ = [
    "HISTORY_DIR",
    "LOCAL_WINDOW_S",
    "RECORDING_SEPARATOR",
    "REGION_BINS",
    "REGION_MIN_SAMPLES",
    "REPORT_DIR",
    "RUNTIME_CLOCKS",
    "RUNTIME_REPEAT",
    "SPEC_GLOBS",
    "UNCERTAINTY_SIGMA",
    "UNKNOWN_MODEL_VERSION",
    "WITHIN_UNCERTAINTY",
    "requirement_id_problem",
    "split_key",
]

#: Spec files, as pytest's ``python_files`` globs (ini ``hevval_files`` overrides them).
SPEC_GLOBS: tuple[str, ...] = ("*.hevval.yaml", "*.hevval.yml")
#: Where run records go, relative to the project root.
HISTORY_DIR = ".hevval/history"
#: Where reports go, relative to the project root.
REPORT_DIR = ".hevval/report"
#: ``local:`` windows, in seconds, when the spec does not say.
LOCAL_WINDOW_S = 30.0
#: ``regions:`` equal bins per variable when ``bins`` is not given.
REGION_BINS = 10
#: A region cell with fewer samples is shown but neither judged by the gate nor coloured as
#: failing: at 10 Hz, 10 s of driving.
REGION_MIN_SAMPLES = 100
#: The coverage factor k a signal's declared ``uncertainty`` is stated at when it gives no
#: ``sigma``: ±2σ, the customary ~95 % statement of instrument accuracy (ASME V&V 20, GUM).
UNCERTAINTY_SIGMA = 2.0
#: What a threshold missed by less than the measurement uncertainty does when the spec's
#: ``measurement.within_uncertainty`` does not say: it still fails.
WITHIN_UNCERTAINTY = "fail"
#: Calls of a model that runs itself per recording, when ``runtime.repeat`` does not say: once,
#: since every extra call is the model's full cost again.
RUNTIME_REPEAT = 1
#: The most calls ``runtime.repeat`` may ask for.
MAX_RUNTIME_REPEAT = 50
#: The clocks a ``runtime:`` gate may judge, the default first: CPU time (the model's own work,
#: which load on the machine barely moves) or wall time.
RUNTIME_CLOCKS = ("cpu", "wall")

#: Between a campaign spec's path and a recording id in a result's key and on the command line.
RECORDING_SEPARATOR = "::"


def split_key(key: str) -> tuple[str, str | None]:
    """(spec path, recording id or None) of a key such as ``specs/i3.hevval.yaml::TripB03``."""
    path, separator, recording = key.partition(RECORDING_SEPARATOR)
    return path, (recording if separator else None)


#: The model version of a run that names none, outside a git checkout.
UNKNOWN_MODEL_VERSION = "unknown"


def requirement_id_problem(text: str) -> str | None:
    """Why ``text`` is no requirement ID, or None: an ID is one non-empty line of printable
    characters without commas or blanks around it (JUnit carries IDs comma-separated)."""
    if not text.strip() or text != text.strip() or "," in text or not text.isprintable():
        return "must be a non-empty requirement ID on one line, without commas or blanks around it"
    return None
