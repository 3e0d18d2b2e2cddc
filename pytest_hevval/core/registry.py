"""Every characteristic, described once: the registry of λ values.

A :class:`Characteristic` says what a λ value is called (``name``, the key everywhere:
results, specs, history, reports), how it is shown (``symbol``, ``label``, ``colour``,
``order``), what physical error explains it, how it weighs into Φ (``default_weight``), whether
every spec scores it (``enabled_by_default``) and how it is computed. The paper's λ1–λ6 come
from the fused pass of :func:`pytest_hevval.core.characteristics.signal_characteristics`
(``compute=None``); λ7 is scored on the tree (``kind="tree"``). Any other characteristic brings
its own ``compute(ref, sim, dt)`` and is registered with :func:`register_characteristic`.

Pure Python: no numpy import at module level, no files, no pytest.
"""

from __future__ import annotations

import math
import re
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Literal

from ..errors import CharacteristicError, did_you_mean
from ..lazy import import_own

__all__ = [
    "CHARACTERISTIC_LABELS",
    "ENTRY_POINT_GROUP",
    "FUSED_CHARACTERISTICS",
    "LAMBDA_ALIASES",
    "PAPER_CHARACTERISTICS",
    "STANDARD_CHARACTERISTICS",
    "Characteristic",
    "CharacteristicKind",
    "CharacteristicValue",
    "compute_characteristic",
    "default_characteristics",
    "describe",
    "get_characteristic",
    "is_registered",
    "load_entry_points",
    "order_names",
    "register_characteristic",
    "registered_characteristics",
    "registry_snapshot",
    "restore_registry",
    "select_characteristics",
]

CharacteristicKind = Literal["signal", "tree"]

#: Entry point group whose modules (or Characteristic objects) register characteristics.
ENTRY_POINT_GROUP = "pytest_hevval.characteristics"

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
# Where user characteristics sort when they do not say: after the paper's seven.
_USER_ORDER = 100
_FALLBACK_COLOUR = "#7F7F7F"


@dataclass(frozen=True)
class CharacteristicValue:
    """A characteristic's score in [0, 1] with named parts that explain it (shown in reports)."""

    value: float
    components: Mapping[str, float] = field(default_factory=dict)


Compute = Callable[[Any, Any, float], "float | CharacteristicValue"]


#: λ1's correlation forms (a spec's ``correlation``) as sentences name them.
_FORMS = {"xcorr": "xcorr coefficient", "pearson": "Pearson's r"}


@dataclass(frozen=True)
class Characteristic:
    """One characteristic λ: its identity, presentation, weight and computation.

    ``explanation`` is a ``str.format`` template for a failing value's physical meaning. It may
    use ``{error}`` (the physical error named by ``error``, e.g. ``mae``), ``{unit}`` (`` V`` or
    empty), ``{range}`` (the reference range), ``{peak_correlation}`` and ``{lag_s}`` (the
    lag and the mean-removed correlation there, :mod:`pytest_hevval.core.lag`), and ``{form}``
    (λ1's form: ``xcorr coefficient`` or ``Pearson's r``).
    """

    name: str
    label: str
    compute: Compute | None = field(default=None, compare=False)
    symbol: str = ""
    kind: CharacteristicKind = "signal"
    error: str | None = None
    explanation: str = ""
    colour: str = _FALLBACK_COLOUR
    order: int = _USER_ORDER
    default_weight: float = 1.0
    enabled_by_default: bool = True

    def __post_init__(self) -> None:
        if not self.symbol:
            object.__setattr__(self, "symbol", self.name)

    @property
    def title(self) -> str:
        """Symbol and label, as headings show it: ``λ3 MAE``, ``peak_error peak error``."""
        return self.label if self.symbol == self.name else f"{self.symbol} {self.label}"

    @property
    def builtin(self) -> bool:
        return self.name in PAPER_CHARACTERISTICS

    @property
    def standard(self) -> bool:
        """One of the field's standard metrics shipped with hevval (docs/metrics.md)."""
        return self.name in STANDARD_CHARACTERISTICS

    def explain(self, errors: Mapping[str, Any], unit: str | None) -> str:
        """The physical meaning of this characteristic's value for one signal ('' if none)."""
        if not self.explanation:
            return ""
        suffix = f" {unit}" if unit else ""
        return self.explanation.format(
            error=float(errors.get(self.error, math.nan)) if self.error else math.nan,
            unit=suffix,
            range=float(errors.get("reference_range", math.nan)),
            peak_correlation=float(errors.get("peak_correlation", math.nan)),
            lag_s=float(errors.get("lag_s", math.nan)),
            form=_FORMS.get(str(errors.get("correlation", "xcorr")), "correlation"),
        )

    def _definition(self) -> tuple[Any, ...]:
        compute = self.compute
        where = (
            None
            if compute is None
            else (getattr(compute, "__module__", None), getattr(compute, "__qualname__", None))
        )
        return (self, where)


_BUILTINS: tuple[Characteristic, ...] = (
    Characteristic(
        name="lag_correlation",
        symbol="λ1",
        label="lag correlation",
        explanation="{form} at zero lag, over the whole record",
        colour="#0072B2",
        order=1,
    ),
    Characteristic(
        name="derivative_match",
        symbol="λ2",
        label="derivative match",
        explanation="fraction of samples whose derivative signs agree",
        colour="#E69F00",
        order=2,
    ),
    Characteristic(
        name="mae",
        symbol="λ3",
        label="MAE",
        error="mae",
        explanation="MAE {error:.4g}{unit} over a {range:.4g}{unit} range",
        colour="#009E73",
        order=3,
    ),
    Characteristic(
        name="rms",
        symbol="λ4",
        label="RMS",
        error="rms",
        explanation="RMS {error:.4g}{unit} over a {range:.4g}{unit} range",
        colour="#56B4E9",
        order=4,
    ),
    Characteristic(
        name="anomaly",
        symbol="λ5",
        label="anomaly (RMS−MAE)",
        error="delta_e",
        explanation="RMS−MAE {error:.4g}{unit} over a {range:.4g}{unit} range",
        colour="#CC79A7",
        order=5,
    ),
    Characteristic(
        name="error_std",
        symbol="λ6",
        label="error spread",
        error="error_std",
        explanation="σ {error:.4g}{unit} over a {range:.4g}{unit} range",
        colour="#D55E00",
        order=6,
    ),
    Characteristic(
        name="emergent",
        symbol="λ7",
        label="emergent",
        kind="tree",
        explanation="mean λ1–λ6 differs from that of the signals below it",
        colour="#F0E442",
        order=7,
    ),
)


@dataclass(frozen=True)
class _StandardCompute:
    """A standard metric's compute, imported on first use: the registry imports no numpy."""

    module: str
    function: str
    #: The module also scores it from a pair's moments (``<function>_from_moments``), which the
    #: engine takes from the λ pass instead of reading the pair again.
    from_moments: bool = True

    def __call__(self, ref: Any, sim: Any, dt: float) -> CharacteristicValue:
        result: CharacteristicValue = getattr(self._module(), self.function)(ref, sim, dt)
        return result

    def with_moments(self, moments: Any) -> CharacteristicValue | None:
        """The value from ``moments`` (``core.standard._moments.Moments``), or None when the
        metric needs the samples themselves."""
        if not self.from_moments:
            return None
        found: CharacteristicValue | None = getattr(
            self._module(), f"{self.function}_from_moments"
        )(moments)
        return found

    def _module(self) -> Any:
        return import_own(f"{__package__}.standard.{self.module}")


def _standard(
    name: str,
    symbol: str,
    label: str,
    module: str,
    colour: str,
    order: int,
    from_moments: bool = True,
    **more: Any,
) -> Characteristic:
    return Characteristic(
        name=name,
        symbol=symbol,
        label=label,
        compute=_StandardCompute(module, f"{name}_characteristic", from_moments),
        colour=colour,
        order=order,
        enabled_by_default=False,
        **more,
    )


# The field's standard metrics (docs/metrics.md): off unless a spec names them in ``metrics``.
# Each scores in [0, 1]; its raw values are the components. Weight 1 in Φ where the score is a
# rating; CV(RMSE) and NMBE are Guideline 14's pass/fail criteria, so they only gate.
_STANDARD: tuple[Characteristic, ...] = (
    _standard("iso18571", "ISO", "ISO/TS 18571 rating", "iso18571", "#332288", 20, False),
    _standard("theil", "1−U", "Theil's U", "theil", "#117733", 21),
    _standard("sprague_geers", "1−C", "Sprague–Geers", "sprague_geers", "#44AA99", 22),
    _standard("russell", "1−RC", "Russell", "sprague_geers", "#88CCEE", 23),
    _standard("kge", "KGE*", "KGE (2009)", "kge", "#DDCC77", 24),
    _standard("kge2012", "KGE′*", "KGE (2012)", "kge", "#CC6677", 25),
    _standard("nse", "NSE*", "Nash–Sutcliffe", "kge", "#AA4499", 26),
    _standard("cvrmse", "1−CV", "CV(RMSE)", "ashrae14", "#882255", 27, default_weight=0.0),
    _standard("nmbe", "1−|NMBE|", "NMBE", "ashrae14", "#661100", 28, default_weight=0.0),
)
#: The standard metrics' names, in report order.
STANDARD_CHARACTERISTICS: tuple[str, ...] = tuple(c.name for c in _STANDARD)

#: The paper's seven characteristics in paper order (λ1 … λ7).
PAPER_CHARACTERISTICS: tuple[str, ...] = tuple(c.name for c in _BUILTINS)
#: λ1–λ6, in the order the fused pass returns them (``SignalCharacteristics.lambdas``); λ7's
#: eq. 13 averages exactly these.
FUSED_CHARACTERISTICS: tuple[str, ...] = PAPER_CHARACTERISTICS[:6]
#: ``lambda1`` … ``lambda7``: the paper's positions, accepted wherever a name is expected.
LAMBDA_ALIASES: dict[str, str] = {f"lambda{c.symbol[1:]}": c.name for c in _BUILTINS}
#: ``λ3 MAE`` etc. for the paper's seven.
CHARACTERISTIC_LABELS: dict[str, str] = {c.name: c.title for c in _BUILTINS}

_lock = threading.Lock()
_registry: dict[str, Characteristic] = {c.name: c for c in _BUILTINS + _STANDARD}
_entry_points_loaded = False


def register_characteristic(characteristic: Characteristic) -> Characteristic:
    """Add ``characteristic`` to the registry and return it.

    Registering the same definition again (the same object, or one equal to it whose
    ``compute`` has the same module and qualified name, as when a ``conftest.py`` is imported
    in several processes) does nothing. A different characteristic under a taken name, a
    built-in's name, or a malformed definition raises :class:`CharacteristicError`.
    """
    if not isinstance(characteristic, Characteristic):
        raise CharacteristicError(
            "register_characteristic() takes a Characteristic "
            f"(got {type(characteristic).__name__})",
            hint="wrap it: register_characteristic(Characteristic(name=..., label=..., "
            "compute=...))",
        )
    _check_definition(characteristic)
    name = characteristic.name
    with _lock:
        existing = _registry.get(name)
        if existing is not None:
            if _same_definition(existing, characteristic):
                return existing
            what = (
                "is a built-in characteristic"
                if existing.builtin or existing.standard
                else "is already registered with a different definition"
            )
            raise CharacteristicError(
                f"characteristic {name!r} {what}",
                key=name,
                hint="choose another name (names are the keys in specs, results and history)",
            )
        if characteristic.order == _USER_ORDER:
            characteristic = _with_order(characteristic, _USER_ORDER + len(_registry))
        _registry[name] = characteristic
    return characteristic


def _same_definition(existing: Characteristic, new: Characteristic) -> bool:
    if existing is new:
        return True
    # A user characteristic registered without an order was given one on registration.
    if new.order == _USER_ORDER:
        existing = _with_order(existing, _USER_ORDER)
    return existing._definition() == new._definition()


def _with_order(characteristic: Characteristic, order: int) -> Characteristic:
    return replace(characteristic, order=order)


def _check_definition(c: Characteristic) -> None:
    def bad(problem: str, hint: str) -> CharacteristicError:
        return CharacteristicError(f"characteristic {c.name!r}: {problem}", key=c.name, hint=hint)

    if not isinstance(c.name, str) or not _NAME.match(c.name):
        raise CharacteristicError(
            f"characteristic name {c.name!r} is not a lower-case identifier",
            hint="use letters, digits and underscores, starting with a letter: 'peak_error'",
        )
    if not isinstance(c.label, str) or not c.label.strip():
        raise bad("needs a non-empty label", "pass label='peak error'")
    if c.kind not in ("signal", "tree"):
        raise bad(f"kind must be 'signal' or 'tree' (got {c.kind!r})", "leave kind at 'signal'")
    if c.kind == "signal" and c.compute is None and c.name not in PAPER_CHARACTERISTICS:
        raise bad("needs compute(ref, sim, dt)", "pass compute=your_function")
    if c.kind == "tree" and c.name not in PAPER_CHARACTERISTICS:
        raise bad("only the built-in λ7 is scored on the tree", "use kind='signal'")
    if c.compute is not None and not callable(c.compute):
        raise bad("compute is not callable", "pass a function compute(ref, sim, dt)")
    weight = c.default_weight
    if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not weight >= 0:
        raise bad(f"default_weight must be a number ≥ 0 (got {weight!r})", "use 1.0")


def get_characteristic(name: str) -> Characteristic:
    """The registered characteristic called ``name``; unknown names get a did-you-mean.

    A name not registered yet may come from an entry point that nothing has loaded (a script
    calling ``load_spec`` directly): the entry points are loaded before giving up.
    """
    found = _registry.get(name)
    if found is None and not _entry_points_loaded:
        load_entry_points()
        found = _registry.get(name)
    if found is None:
        raise CharacteristicError(
            f"unknown characteristic {name!r}",
            key=name,
            hint=did_you_mean(name, _registry) or "registered: " + ", ".join(_registry),
        )
    return found


def is_registered(name: str) -> bool:
    """Whether ``name`` is registered (loading the entry points first if it is not)."""
    if name not in _registry and not _entry_points_loaded:
        load_entry_points()
    return name in _registry


def describe(name: str) -> Characteristic:
    """The registered characteristic, or a plain description of a name found in an old file."""
    found = _registry.get(name)
    if found is not None:
        return found
    return Characteristic(name=name, label=name.replace("_", " "), order=10_000)


def registered_characteristics() -> tuple[Characteristic, ...]:
    """Every registered characteristic, in report order."""
    with _lock:
        return tuple(sorted(_registry.values(), key=lambda c: c.order))


def default_characteristics() -> tuple[Characteristic, ...]:
    """The characteristics a spec scores when it names no ``metrics``."""
    return tuple(c for c in registered_characteristics() if c.enabled_by_default)


def select_characteristics(metrics: Iterable[str] = ()) -> tuple[Characteristic, ...]:
    """The defaults plus the characteristics named in ``metrics``, in report order."""
    wanted = {c.name for c in default_characteristics()}
    wanted.update(get_characteristic(name).name for name in metrics)
    return tuple(c for c in registered_characteristics() if c.name in wanted)


def order_names(names: Iterable[str]) -> list[str]:
    """``names`` in report order; names nobody registered go last, in the order given."""
    seen = list(dict.fromkeys(names))
    return sorted(seen, key=lambda n: (describe(n).order, seen.index(n)))


def compute_characteristic(
    characteristic: Characteristic, ref: Any, sim: Any, dt: float, moments: Any = None
) -> CharacteristicValue:
    """Run a characteristic's ``compute`` and check that it returned a value in [0, 1].

    ``moments``: the pair's ``core.standard._moments.Moments``, from which a standard metric
    built on them is scored without reading ``ref`` and ``sim``.
    """
    compute = characteristic.compute
    if compute is None:
        raise CharacteristicError(
            f"characteristic {characteristic.name!r} has no compute function",
            key=characteristic.name,
        )
    outcome: Any = None
    if moments is not None and isinstance(compute, _StandardCompute):
        outcome = compute.with_moments(moments)
    if outcome is None:
        outcome = compute(ref, sim, dt)
    if isinstance(outcome, CharacteristicValue):
        value: Any = outcome.value
        components = {str(k): float(v) for k, v in dict(outcome.components).items()}
    else:
        value = outcome
        components = {}
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise CharacteristicError(
            f"characteristic {characteristic.name!r} returned {value!r}, not a number",
            key=characteristic.name,
            hint="compute(ref, sim, dt) must return a float in [0, 1] or a CharacteristicValue",
        ) from None
    if not (0.0 <= number <= 1.0):
        raise CharacteristicError(
            f"characteristic {characteristic.name!r} returned {number!r}, outside [0, 1]",
            key=characteristic.name,
            hint="a characteristic is a score in [0, 1] (1 = perfect match); clip or "
            "normalise it, and return a finite value for every signal",
        )
    return CharacteristicValue(number, components)


def load_entry_points() -> None:
    """Import every ``pytest_hevval.characteristics`` entry point, once per process.

    An entry point may name a module (whose import registers characteristics), a
    :class:`Characteristic`, or an iterable of them.
    """
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            loaded = entry.load()
        except Exception as exc:
            raise CharacteristicError(
                f"entry point {entry.name!r} ({entry.value}) of group {ENTRY_POINT_GROUP!r} "
                f"failed to import: {exc}",
                hint="fix or uninstall the package that declares it",
            ) from exc
        if isinstance(loaded, Characteristic):
            register_characteristic(loaded)
        elif isinstance(loaded, (list, tuple)):
            for item in loaded:
                register_characteristic(item)


def registry_snapshot() -> dict[str, Characteristic]:
    """The registry's current contents (to restore after a session that registered more)."""
    with _lock:
        return dict(_registry)


def restore_registry(snapshot: Mapping[str, Characteristic]) -> None:
    with _lock:
        _registry.clear()
        _registry.update(snapshot)
