#!/usr/bin/env python3
"""Writes tests/reference/ruckig_sync_reference.json: synchronised soft-motion problems
(every joint from a moving state to rest, finishing together) with Ruckig 0.19.4's
common duration (Synchronization::Time).

The inputs were found on 2026-12-02 by comparing random synchronised problems (2 and
6 joints; q in ±3 rad, vmax 0.5-3, amax 0.5-5, jmax 1-30, start states anywhere inside
the limits) with Ruckig: the 41 of 40 000 (seed 20240601) where microrobot's stretch
family could not take Ruckig's duration for one non-limiting joint (its target just
past its brake point), and the 6 of a fresh 40 000 (seed 777) that the fallback
(soft::free) still missed before it had the shape with both amax holds.
This script keeps the inputs and recomputes Ruckig's durations:

    tools/baselines/run.sh 1      # builds target/baselines/ruckig_sample
    python3 tools/baselines/sync_reference.py [inputs.json]

inputs.json (optional): {"reached": [problem, ...]}, each problem as
for `microrobot eval trajectory` (q0, q1, v0, a0, vmax, amax, jmax: one value per joint).
"""
import json
import os
import sys

from ruckig_reference import KEYS, ROOT, solve, write

OUT = os.path.join(ROOT, "tests", "reference", "ruckig_sync_reference.json")


def main():
    with open(sys.argv[1] if len(sys.argv) > 1 else OUT) as f:
        problems = json.load(f)["reached"]
    reached = [{**{k: p[k] for k in KEYS}, "duration_s": r["duration"]}
               for p, r in zip(problems, solve(problems, 2))]
    write("ruckig_sync_reference.json", "sync_reference.py",
          "synchronised soft motion: every joint from (q0, v0, a0) to rest at q1, all finishing "
          "together at the smallest common duration (Ruckig Synchronization::Time); no position limits",
          [__doc__.split("This script")[0].strip()], reached=reached)


if __name__ == "__main__":
    main()
