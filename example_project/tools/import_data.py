"""Copy the measured trips and dyno tests this example uses into ``data/`` as Parquet.

Run once by the maintainers; users get the Parquet files with the repository. The source
folders are the dataset copies described in ``data/i3/README.md`` and ``data/camry/README.md``.
Values are parsed with pandas' default parser, which is round-trip exact, so every stored double
is the one the CSV text denotes; only whole columns are dropped, no row or value is changed.

    python tools/import_data.py I3_FOLDER CAMRY_FOLDER
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import pandas as pd

I3_TRIPS = ("A01", "A02", "A06", "A12", "A32", "B02", "B03", "B16", "B17", "B34")
# Trips only docs/closing-the-loop.md walks (walks/), in data/i3/walks/: the campaign's
# `Trip*.parquet` pattern does not reach into that folder.
I3_WALK_TRIPS = ("B24",)

# The channels the model reads, the channels it is scored against, and the ones the
# diagnosis candidates use. Everything else (cabin and vent temperatures, heater internals)
# is left out to keep the repository small.
I3_COLUMNS = (
    "Time [s]",
    "Velocity [km/h]",
    "Elevation [m]",
    "Throttle [%]",
    "Motor Torque [Nm]",
    "Longitudinal Acceleration [m/s^2]",
    "Regenerative Braking Signal ",
    "Battery Voltage [V]",
    "Battery Current [A]",
    "Battery Temperature [°C]",
    "SoC [%]",
    "Heating Power CAN [kW]",
    "AirCon Power [kW]",
    "Ambient Temperature [°C]",
)

CAMRY_TESTS = ("61811011", "61811012", "61811013", "61811014")


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write(frame: pd.DataFrame, target: Path) -> None:
    frame.to_parquet(target, engine="pyarrow", compression="zstd", index=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("i3", type=Path, help="folder holding TripXXX.csv")
    parser.add_argument("camry", type=Path, help="folder holding 'NNNNNNNN Test Data.txt'")
    args = parser.parse_args()
    here = Path(__file__).resolve().parent.parent / "data"

    i3_targets = [(trip, here / "i3") for trip in I3_TRIPS]
    i3_targets += [(trip, here / "i3" / "walks") for trip in I3_WALK_TRIPS]
    for trip, folder in i3_targets:
        source = args.i3 / f"Trip{trip}.csv"
        frame = pd.read_csv(source, sep=";", encoding="latin-1")
        target = folder / f"Trip{trip}.parquet"
        write(frame.loc[:, list(I3_COLUMNS)], target)
        print(f"{sha256(source)}  {source.name} -> {target.name} ({target.stat().st_size} B)")

    for test in CAMRY_TESTS:
        source = args.camry / f"{test} Test Data.txt"
        frame = pd.read_csv(source)
        target = here / "camry" / f"{test}.parquet"
        write(frame, target)
        print(f"{sha256(source)}  {source.name} -> {target.name} ({target.stat().st_size} B)")


if __name__ == "__main__":
    main()
