"""The threshold sidecar beside a spec: ``x.hevval.thresholds.yaml``.

Written by ``--hevval-ratchet`` (:mod:`pytest_hevval.history.ratchet`) and read with the spec:
thresholds in it that are stricter than the spec's own apply. Reading belongs with the spec,
because a sidecar is part of what a spec gates on.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ..core.registry import is_registered, registered_characteristics
from ..errors import SpecError, did_you_mean
from ..files import read_input

__all__ = ["Thresholds", "load_sidecar", "sidecar_path"]

#: Signal path → characteristic → minimum λ.
Thresholds = dict[str, dict[str, float]]


def sidecar_path(spec_path: Path | str) -> Path:
    """``x.hevval.yaml`` → ``x.hevval.thresholds.yaml`` (also for ``.yml``), beside the spec.

    The name does not match the ``*.hevval.yaml`` collection glob, so the sidecar is never
    collected as a spec.
    """
    spec_path = Path(spec_path)
    stem = spec_path.name
    for suffix in (".yaml", ".yml"):
        if stem.endswith(suffix):
            stem = stem[: -len(suffix)]
            break
    return spec_path.with_name(f"{stem}.thresholds.yaml")


def load_sidecar(spec_path: Path | str) -> Thresholds:
    """Read the threshold sidecar of ``spec_path``; ``{}`` when there is none."""
    path = sidecar_path(spec_path)
    try:
        text = read_input(path).decode("utf-8")
    except FileNotFoundError:
        return {}
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(
            f"cannot read the threshold sidecar: {exc}",
            file=str(path),
            hint="fix its permissions or delete it",
        ) from None
    hint = "fix or delete the file; regenerate it with --hevval-ratchet"
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise SpecError(
            f"not valid YAML: {getattr(exc, 'problem', None) or exc}",
            file=str(path),
            line=None if mark is None else mark.line + 1,
            hint=hint,
        ) from None
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise SpecError(
            f"expected a mapping of signal path to thresholds (got {type(document).__name__})",
            file=str(path),
            hint=hint,
        )
    result: Thresholds = {}
    for signal, values in document.items():
        if not isinstance(signal, str) or not isinstance(values, dict):
            raise SpecError(
                "expected 'signal/path: {characteristic: value}'",
                file=str(path),
                key=str(signal),
                hint=hint,
            )
        entry: dict[str, float] = {}
        for name, value in values.items():
            key = f"{signal}.{name}"
            if not isinstance(name, str) or not is_registered(name):
                known = [c.name for c in registered_characteristics()]
                suggestion = did_you_mean(str(name), known)
                raise SpecError(
                    f"unknown characteristic {name!r}" + (f"; {suggestion}" if suggestion else ""),
                    file=str(path),
                    key=key,
                    hint="valid: " + ", ".join(known) + f"; {hint}",
                )
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not 0.0 <= float(value) <= 1.0
            ):
                raise SpecError(
                    f"a λ threshold must be a number in [0, 1] (got {value!r})",
                    file=str(path),
                    key=key,
                    hint=hint,
                )
            entry[name] = float(value)
        result[signal] = entry
    return result
