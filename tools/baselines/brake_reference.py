#!/usr/bin/env python3
"""Writes tests/reference/ruckig_brake_reference.json: single-joint soft-motion problems
that start bound to cross vmax (|v0 + a0|a0|/(2 jmax)| > vmax), solved and sampled by
Ruckig 0.19.4 (its velocity brake, then the time-optimal profile to rest).

Run tools/baselines/run.sh first (it builds target/baselines/ruckig_sample), then
    python3 tools/baselines/brake_reference.py
"""
import random

from ruckig_reference import solve, write

N_CASES, K, SEED = 60, 9, 20261202


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
    gen = draws(random.Random(SEED))
    problems = [next(gen) for _ in range(N_CASES)]
    cases = [dict(p, duration_s=r["duration"], t_s=r["times"], q=[x[0] for x in r["q"]],
                  qd=[x[0] for x in r["qd"]], qdd=[x[0] for x in r["qdd"]])
             for p, r in zip(problems, solve(problems, K))]
    write("ruckig_brake_reference.json", "brake_reference.py",
          "one joint from a state bound to cross vmax (|v0 + a0|a0|/(2 jmax)| > vmax) to rest at q1; "
          "symmetric limits; no position limits. Ruckig brakes (jerk -jmax, holding -amax, until v = vmax "
          "or until the stop velocity reaches -vmax), then plans time-optimally",
          [f"t_s: K = {K} evenly spaced times over [0, duration_s], then duration_s + 0.1 (at rest)"],
          seed=SEED, cases=cases)


if __name__ == "__main__":
    main()
