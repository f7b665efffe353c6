"""Pad hold and landing against vision latency, with and without the prediction (issue 18).

Run: ``python benchmarks/bench_pad_latency.py [--latency-ms 540 300 ...] [--only hold|land]``.
Each flight is the lockstep flight of ``tests/pilot/test_pad_latency.py`` (latency in sim
time, so the figures do not depend on this machine's speed): pad hold started 0.6 m off for
20 s, and PAD_MODE LAND from 3 m east of the pad at 4.5 m; for each latency it flies with the
prediction, without it (gains derived for that loop's delay), and without it with the gains
the pilot had before (kp 1.2, ki 0.15). About 30-60 s of wall time per flight.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.pilot.pad_hold import PadHoldParams
from tests.pilot.test_pad_latency import hold_from_0_6_m, land_from_3_m

VARIANTS = (
    ("predicted", True, None),
    ("not predicted, gains for its delay", False, None),
    ("not predicted, previous gains 1.2/0.15", False, PadHoldParams(kp=1.2, ki=0.15)),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--latency-ms", type=float, nargs="+", default=[540.0])
    ap.add_argument("--only", choices=("hold", "land"), default=None)
    args = ap.parse_args()
    for ms in args.latency_ms:
        for label, predict, params in VARIANTS:
            if args.only != "land":
                start, settled, late = hold_from_0_6_m(predict, params, ms / 1e3)
                print(f"{ms:.0f} ms, {label}: hold from {start:.2f} m: within 0.1 m from "
                      f"{settled:.1f} s on; largest offset 10-20 s {late * 100:.1f} cm", flush=True)
            if args.only != "hold":
                start, landed, miss = land_from_3_m(predict, params, ms / 1e3)
                print(f"{ms:.0f} ms, {label}: LAND from {start:.2f} m: landed after "
                      f"{landed:.1f} s, {miss * 100:.1f} cm from the centre", flush=True)


if __name__ == "__main__":
    main()
