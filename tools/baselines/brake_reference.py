#!/usr/bin/env python3
"""Writes tests/reference/ruckig_brake_reference.json: single-joint soft-motion problems
that start bound to cross vmax (|v0 + a0|a0|/(2 jmax)| > vmax), solved and sampled by
Ruckig 0.19.4 (its velocity brake, then the time-optimal profile to rest).

Run tools/baselines/run.sh first (it builds target/baselines/ruckig_sample), then
    python3 tools/baselines/brake_reference.py
"""
import json
import os
import random
import subprocess

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
SAMPLER = os.path.join(ROOT, "target", "baselines", "ruckig_sample")
OUT = os.path.join(ROOT, "tests", "reference", "ruckig_brake_reference.json")
N_CASES, K = 60, 9


def draws(rng):
    """Uniform draws as in the comparison of 2026-12-02; only states that must brake."""
    while True:
        vmax, amax, jmax = rng.uniform(0.5, 3), rng.uniform(0.5, 5), rng.uniform(1, 30)
        v0, a0 = rng.uniform(-vmax, vmax), rng.uniform(-amax, amax)
        if abs(v0 + a0 * abs(a0) / (2 * jmax)) <= vmax:
            continue
        yield dict(q0=rng.uniform(-3, 3), q1=rng.uniform(-3, 3), v0=v0, a0=a0,
                   vmax=vmax, amax=amax, jmax=jmax)


def main():
    gen = draws(random.Random(20261202))
    problems = [next(gen) for _ in range(N_CASES)]
    lines = "".join(
        "1 " + " ".join(repr(p[k]) for k in ("q0", "q1", "v0", "a0", "vmax", "amax", "jmax")) + f" {K}\n"
        for p in problems)
    out = subprocess.run([SAMPLER], input=lines, capture_output=True, text=True, check=True).stdout
    cases = []
    for p, line in zip(problems, out.splitlines()):
        r = json.loads(line)
        if "error" in r:
            raise SystemExit(f"ruckig refused {p}: {r['error']}")
        cases.append(dict(p, duration_s=r["duration"], t_s=r["times"],
                          q=[x[0] for x in r["q"]], qd=[x[0] for x in r["qd"]],
                          qdd=[x[0] for x in r["qdd"]]))
    doc = {
        "problem": "one joint from a state bound to cross vmax (|v0 + a0|a0|/(2 jmax)| > vmax) to rest at q1; "
                   "symmetric limits; no position limits. Ruckig brakes (jerk -jmax, holding -amax, until v = vmax "
                   "or until the stop velocity reaches -vmax), then plans time-optimally",
        "units": "radians, seconds",
        "generator": {"script": "tools/baselines/brake_reference.py", "rng_seed": 20261202,
                      "sampler": "tools/baselines/ruckig_sample.cpp, g++ -O3 -march=native",
                      "ruckig": "0.19.4"},
        "notes": ["t_s: K = 9 evenly spaced times over [0, duration_s], then duration_s + 0.1 (at rest)"],
        "cases": cases,
    }
    with open(OUT, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(f"wrote {len(cases)} cases to {OUT}")


if __name__ == "__main__":
    main()
