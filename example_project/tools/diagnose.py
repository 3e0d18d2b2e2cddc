"""Which candidate explains the residual of one signal of a spec with a callable model?

Runs the spec's model, forms the residual (reference − model) of one signal and hands it, with
the spec's declared ``candidates`` (and with ``--channels`` every other measured channel), to
the residual diagnosis of pytest-hevval. An instantaneous signal such as ``P_batt`` shows an
unmodelled load directly; a cumulative one only shows its running sum.

    python tools/diagnose.py specs/i3-B03-winter-v1.hevval.yaml --signal P_batt
    python tools/diagnose.py specs/bus-mild-hybrid.hevval.yaml --signal Teng --channels
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from pytest_hevval.core.diagnosis import Candidate, diagnose_residual
from pytest_hevval.spec.expressions import parse_signal

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def walk(sets: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [n for node in sets for n in (node, *walk(node.get("children", [])))]


def find(sets: list[dict[str, Any]], name: str) -> dict[str, Any]:
    for node in sets:
        if node["signal"] == name:
            return node
        try:
            return find(node.get("children", []), name)
        except KeyError:
            continue
    raise KeyError(name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", type=Path)
    parser.add_argument("--signal", required=True, help="signal name in the spec's tree")
    parser.add_argument(
        "--channels", action="store_true", help="also try every other measured channel"
    )
    args = parser.parse_args()
    spec = yaml.safe_load(args.spec.read_text(encoding="utf-8"))
    data = pd.read_parquet((args.spec.parent / spec["reference"]["path"]).resolve())
    time_name = spec["reference"]["time"]
    time = data[time_name].to_numpy(dtype=np.float64)
    columns = {str(c): data[c].to_numpy(dtype=np.float64) for c in data.columns}

    model = spec["model"]
    module_name, _, function_name = model["callable"].partition(":")
    simulate = getattr(importlib.import_module(module_name), function_name)
    inputs = data.loc[:, [time_name, *model["inputs"]]]
    sim = simulate(inputs, **model.get("params", {}))
    sim_time = sim[model.get("time", "time")].to_numpy(dtype=np.float64)
    node = find(spec["sets"], args.signal)
    reference = parse_signal(node["ref"]).evaluate(columns, time)
    simulated = parse_signal(node["sim"]).evaluate(
        {str(c): sim[c].to_numpy(dtype=np.float64) for c in sim.columns}, sim_time
    )

    candidates = [
        Candidate(name, "declared", parse_signal(source).evaluate(columns, time))
        for name, source in spec.get("candidates", {}).items()
    ]
    if args.channels:
        # Channels the tree itself scores are effects, not causes.
        used = {c for n in walk(spec["sets"]) for c in parse_signal(n["ref"]).columns}
        used.add(time_name)
        candidates += [
            Candidate(name, "channel", values)
            for name, values in columns.items()
            if name not in used and np.isfinite(values).all()
        ]
    dt = float(np.median(np.diff(time)))
    result = diagnose_residual(reference, simulated, dt=dt, candidates=candidates)
    print(f"{spec.get('name', args.spec.name)}: residual of {args.signal}")
    print(f"  {result.summary}")
    for finding in result.candidates:
        low, high = finding.interval
        print(
            f"  {finding.rank}. {finding.name:16s} explains {finding.explained_fraction:6.1%}"
            f"  coefficient {finding.coefficient:+.4g} [{low:+.4g}, {high:+.4g}]"
            f"  {'selected' if finding.selected else 'not selected'}"
        )


if __name__ == "__main__":
    main()
