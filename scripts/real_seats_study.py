#!/usr/bin/env python3
"""Held-out placements of a seat plate: train ``aacmm calibrate`` and ``aacmm close-loop`` (default options)
on one placement, apply each model with ``aacmm tip`` to the other placements, and report the seat spread
(2 sigma per hole) and the distance error. Method and definitions: calibration/placements.py.

    python scripts/real_seats_study.py                      # the real Panda data of examples/
    python scripts/real_seats_study.py --train front -o out/seats
    python scripts/real_seats_study.py --train front+right,front+back-high,right+back-high   # two at once
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.placements import markdown_table, placement_study  # noqa: E402


def main(argv=None) -> int:
    data = ROOT / "examples" / "data" / "real-panda-seats"
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=data, help="folder with artefacts.toml and one folder per placement")
    p.add_argument("--arm", type=Path, default=data / "panda-with-inertials.urdf", help="nominal arm")
    p.add_argument("--tip-frame", default="ball_link", help="tip link of a URDF arm")
    p.add_argument("--train", default=None,
                   help="comma-separated training placements (default every one); a+b trains on a and b together")
    p.add_argument("--methods", default="calibrate,close-loop", help="calibrate, close-loop or both")
    p.add_argument("--calibrate-options", default="", help="extra options of aacmm calibrate (one string)")
    p.add_argument("--loop-options", default="", help="extra options of aacmm close-loop (one string)")
    p.add_argument("-o", "--output", type=Path, default=Path("out/real-seats"), help="output folder")
    args = p.parse_args(argv)
    rows = placement_study(args.data, args.arm, args.tip_frame, args.output,
                           train=args.train.split(",") if args.train else None,
                           methods=tuple(args.methods.split(",")),
                           options={"calibrate": args.calibrate_options.split(),
                                    "close-loop": args.loop_options.split()},
                           progress=lambda m: print(m, file=sys.stderr, flush=True))
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "results.json").write_text(json.dumps([r.to_dict() for r in rows], indent=1) + "\n")
    print(markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
