"""Pinocchio references for robots loaded from URDF: tests/reference/urdf_reference.json.

    tools/baselines/run_urdf_reference.sh     # venv with pinned, hash-checked packages, then this

For each robot (a URDF, or an overlay TOML naming one with base_link, tip_link and [lock]),
Pinocchio builds the model from the URDF, locks every joint off the base->tip path
(buildReducedModel at the overlay's [lock] value, else 0 clamped into the joint's limits; the
same rule as microrobot_model's loader), and evaluates at 50 states (30 uniform inside the
limits, 10 within 1e-3 of a limit, 10 with joints at singular values):

  * the pose (4x4) of every link frame on the path, base frame;
  * the Jacobian of the tip link frame, LOCAL_WORLD_ALIGNED (rows vx vy vz wx wy wz);
  * M (crba, both triangles), g (computeGeneralizedGravity), C(q, qd) qd = rnea(q, qd, 0) - g,
    tau = rnea(q, qd, qdd): rigid-body terms only (Pinocchio's rnea has no <dynamics> friction).

The states come from a fixed seed, so a rerun writes the same file.
"""

import json
import sys
import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[2]
REF = ROOT / "tests" / "reference"
ROBOTS = [
    ("ur5", REF / "urdf" / "ur5_robot.urdf"),
    ("panda", REF / "urdf" / "panda.toml"),
    ("test_arm", REF / "urdf" / "test_arm.toml"),
]
# Joints (1-based in the reduced model) set to a singular value in the last ten states:
# UR5 elbow straight (3) and wrist 2 at zero (5: wrist axes 4 and 6 aligned); Panda
# joint 2 at zero (axes 1 and 3 aligned) and joint 6 at its lower limit.
SINGULAR = {"ur5": {3: 0.0, 5: 0.0}, "panda": {2: 0.0, 6: -0.0175}, "test_arm": {}}


def selection(path):
    """URDF path, base_link, tip_link, lock values: from an overlay or the bare URDF."""
    if path.suffix == ".urdf":
        return path, None, None, {}
    overlay = tomllib.loads(path.read_text())
    head = overlay["robot"]
    return (
        path.parent / head["urdf"],
        head.get("base_link"),
        head.get("tip_link"),
        overlay.get("lock", {}),
    )


def frame_id(model, name):
    fid = model.getFrameId(name, pin.BODY)
    if fid >= len(model.frames):
        sys.exit(f"no link {name} in the model")
    return fid


def path_links(model, base, tip):
    """Link (BODY) frame names from base to tip, following parent frames."""
    names = []
    f = frame_id(model, tip)
    while True:
        frame = model.frames[f]
        if frame.type == pin.BODY:
            names.append(frame.name)
            if frame.name == base:
                break
        if f == 0:
            sys.exit(f"no path from {base} to {tip}")
        f = frame.parentFrame
    return names[::-1]


def build(name, path):
    urdf, base, tip, lock = selection(path)
    full = pin.buildModelFromUrdf(str(urdf))
    # The root link: the first BODY frame (Pinocchio's root is the URDF root link).
    root = next(f.name for f in full.frames if f.type == pin.BODY)
    base = base or root
    if base != root:
        sys.exit(f"{name}: base_link must be the root link {root} for this script")
    if tip is None:
        # The child link of the last moving joint (the moving joints form one path).
        last = full.njoints - 1
        tip = next(f.name for f in full.frames if f.type == pin.BODY and f.parentJoint == last
                   and full.frames[f.parentFrame].type == pin.JOINT)
    links = path_links(full, base, tip)
    tip_joint = full.frames[frame_id(full, tip)].parentJoint
    on_path = set()
    j = tip_joint
    while j > 0:
        on_path.add(j)
        j = full.parents[j]
    q_ref = pin.neutral(full)
    locked = []
    for j in range(1, full.njoints):
        if j in on_path:
            continue
        jn = full.names[j]
        jm = full.joints[j]
        if jm.nq != 1:
            sys.exit(f"{name}: locking joint {jn} with nq = {jm.nq} is not supported here")
        lo, hi = full.lowerPositionLimit[jm.idx_q], full.upperPositionLimit[jm.idx_q]
        q_ref[jm.idx_q] = lock.get(jn, min(max(0.0, lo), hi))
        locked.append(j)
    model = pin.buildReducedModel(full, locked, q_ref)
    return model, links, tip


def one_turn(model):
    """Per velocity index: a continuous joint (cos/sin in Pinocchio's q), whose
    limits are one turn [-pi, pi] in microrobot_model."""
    out = np.zeros(model.nv, dtype=bool)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nq == 2 and jm.nv == 1:
            out[jm.idx_v] = True
    return out


def to_pin(model, q):
    """Pinocchio's configuration for joint positions q (angles or travel)."""
    return pin.integrate(model, pin.neutral(model), q)


def states(model, name, rng):
    n = model.nv
    turn = one_turn(model)
    lo, hi = np.zeros(n), np.zeros(n)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if not turn[jm.idx_v]:
            lo[jm.idx_v] = model.lowerPositionLimit[jm.idx_q]
            hi[jm.idx_v] = model.upperPositionLimit[jm.idx_q]
    lo[turn], hi[turn] = -np.pi, np.pi
    out = []
    for k in range(50):
        q = lo + (hi - lo) * rng.uniform(size=n)
        if 30 <= k < 40:
            # every joint within 1e-3 of one of its limits
            side = rng.uniform(size=n) < 0.5
            q = np.where(side, lo + 1e-3 * rng.uniform(size=n), hi - 1e-3 * rng.uniform(size=n))
        elif k >= 40:
            for j, v in SINGULAR[name].items():
                q[j - 1] = v
        qd = rng.uniform(-2.0, 2.0, size=n)
        qdd = rng.uniform(-5.0, 5.0, size=n)
        out.append((q, qd, qdd))
    return out


def main():
    rng = np.random.default_rng(20261203)
    robots = []
    for name, path in ROBOTS:
        model, links, tip = build(name, path)
        data = model.createData()
        tip_id = frame_id(model, tip)
        cases = []
        for q_ours, qd, qdd in states(model, name, rng):
            q = to_pin(model, q_ours)
            pin.forwardKinematics(model, data, q)
            pin.updateFramePlacements(model, data)
            poses = {l: data.oMf[frame_id(model, l)].homogeneous.tolist() for l in links}
            jac = pin.computeFrameJacobian(model, data, q, tip_id, pin.LOCAL_WORLD_ALIGNED)
            m = pin.crba(model, data, q)
            m = np.triu(m) + np.triu(m, 1).T
            g = pin.computeGeneralizedGravity(model, data, q)
            c = pin.rnea(model, data, q, qd, np.zeros(model.nv)) - g
            tau = pin.rnea(model, data, q, qd, qdd)
            cases.append({
                "q": q_ours.tolist(), "qd": qd.tolist(), "qdd": qdd.tolist(),
                "link_poses": poses, "tip_jacobian": jac.tolist(),
                "mass_matrix": m.tolist(), "gravity": g.tolist(),
                "coriolis": c.tolist(), "tau": tau.tolist(),
            })
        robots.append({
            "name": name,
            "file": str(path.relative_to(REF)),
            "joints": [model.names[j] for j in range(1, model.njoints)],
            "links": links,
            "tip_link": tip,
            "damping": model.damping.tolist(),
            "friction": model.friction.tolist(),
            "cases": cases,
        })
    out = {
        "generator": "tools/baselines/urdf_reference.py",
        "pinocchio": pin.__version__,
        "example_robot_data": "6.0.0",
        "gravity_mps2": model.gravity.linear.tolist(),
        "robots": robots,
    }
    (REF / "urdf_reference.json").write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print(f"wrote {REF / 'urdf_reference.json'}: "
          + ", ".join(f"{r['name']} {len(r['cases'])} states" for r in robots))


if __name__ == "__main__":
    main()
