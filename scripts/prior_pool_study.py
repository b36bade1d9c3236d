#!/usr/bin/env python3
"""Exploration, not a default: the seat studies with the evidence's geometric prior groups pooled into one scale.

By default the evidence (calibration/prior.py, :func:`calibration.prior.update_scales`) gives each group of the
description's parameters its own scale (lengths, joint offsets, axis angles, the tip offset). This study runs
``scripts/real_seats_study.py`` or ``scripts/sim_seats_study.py`` in one process with that fixed point replaced, for
the groups named by ``--pool``, by one pooled fixed point (``tau^2 = sum z^2 / sum gamma`` over the pooled groups'
seen parameters, each group then at that scale, its ceiling kept), or with groups pinned at a given scale
(``--pin``). Every other rule of the evidence is unchanged. It wraps the function for this process only; nothing in
the package changes. Measured in docs/studies/close-loop.md ("The distance error: what it is made of").

    python scripts/prior_pool_study.py real --methods calibrate,close-loop -o out/pool
    python scripts/prior_pool_study.py real --pool "" --pin "lengths=3" --methods calibrate -o out/pin
    python scripts/prior_pool_study.py sim --methods calibrate -o out/pool-sim -- --capture sweep
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import calibration.prior as prior  # noqa: E402

CALIBRATE = sys.modules["calibration.calibrate"]       # the module (the package's attribute is the function)

GEOMETRY = (prior.GROUP_LENGTHS, prior.GROUP_OFFSETS, prior.GROUP_ANGLES, prior.GROUP_TIP)


def pooled_update(pool: tuple[str, ...], pins: dict[str, float]):
    """:func:`calibration.prior.update_scales` with the groups of ``pool`` sharing one fixed point and those of
    ``pins`` at a given scale."""
    plain = prior.update_scales

    def update(scales, spec, kept, delta, rho):
        new, gamma = plain(scales, spec, kept, delta, rho)
        kept = np.asarray(kept, dtype=int)
        groups = spec.groups_of(kept)
        z2 = gam = 0.0
        for g in pool:
            if g in groups and g not in spec.physical:
                sel = np.isin(kept, groups[g]) & (rho < prior.BARELY_SEEN)
                gam += float(np.sum(1.0 - rho[sel]))
                z2 += float(np.sum((delta[sel] / spec.size[kept[sel]]) ** 2))
        if gam >= prior.MIN_EFFECTIVE:
            for g in pool:
                if g in new:
                    new[g] = spec.bounded(g, math.sqrt(z2 / gam))
        for g, v in pins.items():
            if g in new:
                new[g] = v
        return new, gamma
    return update


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("study", choices=("real", "sim"))
    p.add_argument("--pool", default=",".join(GEOMETRY), help="comma-separated groups sharing one scale ('' none)")
    p.add_argument("--pin", default="", help="comma-separated group=scale pinned (e.g. 'lengths=3')")
    p.add_argument("--methods", default="calibrate,close-loop")
    p.add_argument("-o", "--output", type=Path, required=True)
    p.add_argument("rest", nargs="*", help="after --: options of the study script")
    args = p.parse_args(argv)
    pool = tuple(g for g in args.pool.split(",") if g)
    pins = {k: float(v) for k, v in (s.split("=") for s in args.pin.split(",") if s)}
    CALIBRATE.update_scales = pooled_update(pool, pins)    # what calibrate() calls, for this process only
    study = "real_seats_study" if args.study == "real" else "sim_seats_study"
    module = __import__(study)
    return int(module.main(["--methods", args.methods, "-o", str(args.output), *args.rest]))


if __name__ == "__main__":
    sys.exit(main())
