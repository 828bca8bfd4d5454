#!/usr/bin/env python3
"""Convert the project's TOML/JSON inputs into plain whitespace-separated text
files that the C++ benchmarks read (no JSON/TOML library needed in C++).

Reads (read-only):
  config/robots/seed-arm.toml
  tests/reference/arm_reference.json
  tests/reference/trajectory_reference.json
  tests/reference/online_trajectory_reference.json
Writes into ./data/ (the current directory):
  model.txt       gravity (3), then per joint: theta d a alpha [rad, m], qmin qmax vmax amax jmax,
                  mass, com(3) [m], inertia 3x3 [kg m^2] (about COM, DH frame i), rotor inertia [kg m^2]
  arm_cases.txt   ncases, then per case q qd qdd fk(16) jac(36) M(36) g(6) c(6) tau(6)
  table4.txt      6 lines: p0 p1 vmax amax jmax ; then the reference duration
  online_sync.txt n, then per case p0(6) v0(6) a0(6) p1(6) vmax(6) amax(6) jmax(6) duration
"""
import json
import math
import os
import tomllib

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
OUT = os.path.join(os.getcwd(), "data")
os.makedirs(OUT, exist_ok=True)
D2R = math.pi / 180.0

with open(os.path.join(ROOT, "config/robots/seed-arm.toml"), "rb") as f:
    robot = tomllib.load(f)
assert "tool" not in robot and "payload" not in robot, "tool/payload tables not handled"
with open(f"{OUT}/model.txt", "w") as f:
    f.write(" ".join(repr(float(x)) for x in robot["robot"]["gravity_mps2"]) + "\n")
    f.write(f"{len(robot['joints'])}\n")
    for j in robot["joints"]:
        assert j["kind"] == "revolute"
        for k in ("gear_ratio", "viscous_friction_nms", "coulomb_friction_nm"):
            assert k not in j or j[k] in (0.0, 1.0), (k, j)
        dh, lim, link = j["dh"], j["limits"], j["link"]
        row = [dh["theta_deg"] * D2R, dh["d_mm"] * 1e-3, dh["a_mm"] * 1e-3, dh["alpha_deg"] * D2R,
               lim["min_deg"] * D2R, lim["max_deg"] * D2R, lim["vel_deg_s"] * D2R,
               lim["acc_deg_s2"] * D2R, lim["jerk_deg_s3"] * D2R,
               link["mass_kg"]] + [c * 1e-3 for c in link["com_mm"]] + \
              [link["inertia_kgmm2"][r][c] * 1e-6 for r in range(3) for c in range(3)] + \
              [link.get("rotor_inertia_kgmm2", 0.0) * 1e-6]
        f.write(" ".join(repr(float(x)) for x in row) + "\n")

arm = json.load(open(os.path.join(ROOT, "tests/reference/", "arm_reference.json")))
with open(f"{OUT}/arm_cases.txt", "w") as f:
    f.write(f"{len(arm['cases'])}\n")
    for c in arm["cases"]:
        vals = c["q"] + c["qd"] + c["qdd"]
        vals += [x for r in c["fk"] for x in r]
        vals += [x for r in c["jacobian"] for x in r]
        vals += [x for r in c["mass_matrix"] for x in r]
        vals += c["gravity_torque"] + c["coriolis_torque"] + c["tau"]
        f.write(" ".join(repr(float(x)) for x in vals) + "\n")

tr = json.load(open(os.path.join(ROOT, "tests/reference/", "trajectory_reference.json")))
with open(f"{OUT}/table4.txt", "w") as f:
    for j in tr["joints"]:
        f.write(" ".join(repr(float(x)) for x in (j["theta_i_rad"], j["theta_f_rad"], j["vmax_radps"],
                                                  j["amax_radps2"], j["jmax_radps3"])) + "\n")
    f.write(repr(float(tr["synchronized_6dof"]["ruckig_duration_s"])) + "\n")

on = json.load(open(os.path.join(ROOT, "tests/reference/", "online_trajectory_reference.json")))
with open(f"{OUT}/online_sync.txt", "w") as f:
    f.write(f"{len(on['synchronized'])}\n")
    for s in on["synchronized"]:
        vals = s["p0"] + s["v0"] + s["a0"] + s["p1"] + s["vmax"] + s["amax"] + s["jmax"] + [s["duration_s"]]
        f.write(" ".join(repr(float(x)) for x in vals) + "\n")
print("wrote", sorted(os.listdir(OUT)))
