"""Export the EV model's run of every i3 trip to one Parquet file each, as a simulation tool
(Simulink, Dymola, GT-SUITE, AVL Cruise) run in batch leaves them.

    python tools/export_runs.py            # writes exports/v2/TripA01.parquet, ...

``exports/i3-campaign-v2-exported.hevval.yaml`` then scores these files against the measured
trips (``model: {path: "v2/{id}.parquet"}``): the campaign of ``specs/i3-campaign-v2``, with
the model given as its exported output instead of a callable.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))

from models.ev import simulate  # noqa: E402  (the example's model package)


def main() -> None:
    target = HERE / "exports" / "v2"
    target.mkdir(parents=True, exist_ok=True)
    for trip in sorted((HERE / "data" / "i3").glob("Trip*.parquet")):
        measured = pd.read_parquet(trip)
        run = simulate(measured, version=2)
        out = target / trip.name
        run.to_parquet(out, index=False)
        print(f"{out.relative_to(HERE)}: {len(run)} samples")


if __name__ == "__main__":
    main()
