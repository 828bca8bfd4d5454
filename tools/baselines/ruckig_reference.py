"""What the reference generators share: Ruckig 0.19.4 (tools/baselines/ruckig_sample.cpp,
built by run.sh) solving and sampling problems, and the reference files' common header."""
import json
import os
import subprocess

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
SAMPLER = os.path.join(ROOT, "target", "baselines", "ruckig_sample")
KEYS = ("q0", "q1", "v0", "a0", "vmax", "amax", "jmax")


def solve(problems, k):
    """Ruckig's trajectory for each problem (values per joint as lists, or scalars for one
    joint), sampled at k evenly spaced times and once after the end: one dict each with
    duration, times and q, qd, qdd, jerk indexed [time][joint]."""
    def line(p):
        per_joint = [p[key] if isinstance(p[key], list) else [p[key]] for key in KEYS]
        return f"{len(per_joint[0])} " + " ".join(repr(float(x)) for xs in per_joint for x in xs) + f" {k}\n"
    out = subprocess.run([SAMPLER], input="".join(line(p) for p in problems), capture_output=True,
                         text=True, check=True).stdout.splitlines()
    results = [json.loads(r) for r in out]
    for p, r in zip(problems, results):
        if "error" in r:
            raise SystemExit(f"ruckig refused {p}: {r['error']}")
    return results


def write(name, script, problem, notes, seed=None, **data):
    """Writes tests/reference/<name> with the common header (the draws' seed, if any) and `data`."""
    doc = {
        "problem": problem,
        "units": "radians, seconds",
        "generator": {"script": f"tools/baselines/{script}",
                      **({"rng_seed": seed} if seed is not None else {}),
                      "sampler": "tools/baselines/ruckig_sample.cpp, g++ -O3 -march=native",
                      "ruckig": "0.19.4"},
        "notes": notes,
        **data,
    }
    path = os.path.join(ROOT, "tests", "reference", name)
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(f"wrote {path}")
