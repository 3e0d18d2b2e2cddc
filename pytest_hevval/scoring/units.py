"""A signal side brought to the signal's unit: pint's conversions and the spec's scale and offset.

Each error names the spec key (``ref_unit``, ``sim_scale``, …) that asked for the conversion.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ExpressionError
from ..spec.model import SignalSpec

__all__ = ["convert_units", "scaled"]

FloatArray = npt.NDArray[np.float64]


def scaled(
    values: FloatArray, scale: float, offset: float, node: SignalSpec, side: str
) -> FloatArray:
    """``values * scale + offset``, or the error naming the key that takes them beyond what
    float64 holds (the range the signal is normalised by included)."""
    with np.errstate(over="ignore", invalid="ignore"):
        result = values * scale + offset
        finite = result[np.isfinite(result)]
        spread = float(finite.max() - finite.min()) if finite.size else 0.0
    overflowed = np.isinf(result) & np.isfinite(values)
    if not (bool(overflowed.any()) or math.isinf(spread)):
        return result
    prefix = "ref" if side == "reference" else "sim"
    key = f"{prefix}_scale" if scale != 1.0 else f"{prefix}_offset"
    largest = float(np.nanmax(np.abs(values))) if values.size else 0.0
    raise ExpressionError(
        f"{key} {scale if scale != 1.0 else offset:g} takes the {side} side beyond what float64 "
        f"holds (its largest magnitude is {largest:g})",
        key=f"{node.key}.{key}",
        line=node.line,
        hint=f"check {key}: it converts the data to the signal's unit",
    )


def convert_units(
    values: FloatArray, source_unit: str, target_unit: str, node: SignalSpec, side: str
) -> FloatArray:
    try:
        import pint
    except ImportError:
        from ..errors import MissingExtraError

        raise MissingExtraError.for_extra("unit conversion", "units", "pint") from None
    registry = _unit_registry()
    try:
        quantity = registry.Quantity(values, source_unit)
        return np.asarray(quantity.to(target_unit).magnitude, dtype=np.float64)
    except (pint.errors.PintError, ValueError, TypeError) as exc:
        key = "ref_unit" if side == "reference" else "sim_unit"
        raise ExpressionError(
            f"cannot convert {source_unit!r} to {target_unit!r}: {exc}",
            key=f"{node.key}.{key}",
            line=node.line,
        ) from None


_REGISTRY: Any = None


def _unit_registry() -> Any:
    global _REGISTRY
    if _REGISTRY is None:
        import pint

        _REGISTRY = pint.UnitRegistry()
    return _REGISTRY
