//! The UR5 (bare URDF) and the Panda (overlay: tip at the hand's TCP, fingers
//! locked) against `tests/reference/urdf_reference.json`, 50 states each from
//! Pinocchio 4.1 (`tools/baselines/urdf_reference.py`): the pose of every link
//! on the base→tip path, the tip Jacobian, M, g, C·qd and τ, 1e-9 relative with
//! a 1e-12 absolute floor. Pinocchio's τ is rigid-body only: our τ minus the
//! `<dynamics>` friction is held to it, and the friction separately.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use microrobot_model::{
    JointVector, ModelData, Robot, coriolis_torque, forward_dynamics, gravity_torque, jacobian,
    mass_matrix, rnea,
};
use serde_json::Value;
use std::path::Path;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../tests/reference");

fn reference() -> Value {
    let text = std::fs::read_to_string(Path::new(DIR).join("urdf_reference.json"))
        .expect("reference file readable");
    serde_json::from_str(&text).expect("reference is JSON")
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn vector(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(num).collect()
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("array").iter().map(vector).collect()
}

fn joint_vector(v: &Value) -> JointVector {
    let mut out = JointVector::zeros();
    for (i, x) in vector(v).into_iter().enumerate() {
        out[i] = x;
    }
    out
}

#[track_caller]
fn close(what: &str, got: f64, want: f64) {
    let tol = (1e-9 * want.abs()).max(1e-12);
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got:e}, reference {want:e} (diff {:e} > {tol:e})",
        (got - want).abs()
    );
}

fn robots() -> Vec<(Robot, Value)> {
    let r = reference();
    r["robots"]
        .as_array()
        .expect("robots")
        .iter()
        .map(|entry| {
            let file = entry["file"].as_str().expect("file");
            let robot =
                Robot::from_file(&Path::new(DIR).join(file)).unwrap_or_else(|e| panic!("{e}"));
            (robot, entry.clone())
        })
        .collect()
}

#[test]
fn joints_links_and_gravity_are_the_references() {
    let r = reference();
    for (robot, entry) in robots() {
        let name = entry["name"].as_str().expect("name");
        assert!(robot.is_placed(), "{name}");
        let joints: Vec<&str> = robot.joints().iter().map(|j| j.name.as_str()).collect();
        let want: Vec<&str> = entry["joints"]
            .as_array()
            .expect("joints")
            .iter()
            .map(|v| v.as_str().expect("joint name"))
            .collect();
        assert_eq!(joints, want, "{name}: joints");
        let links: Vec<&str> = robot.links().iter().map(|l| l.name.as_str()).collect();
        let want: Vec<&str> = entry["links"]
            .as_array()
            .expect("links")
            .iter()
            .map(|v| v.as_str().expect("link name"))
            .collect();
        assert_eq!(links, want, "{name}: links on the path");
        let g = vector(&r["gravity_mps2"]);
        for k in 0..3 {
            assert_eq!(robot.gravity()[k], g[k], "{name}: gravity");
        }
    }
}

#[test]
fn every_case_matches_pinocchio() {
    for (robot, entry) in robots() {
        let name = entry["name"].as_str().expect("name");
        let tip = entry["tip_link"].as_str().expect("tip");
        let n = robot.dof();
        let mut data = ModelData::new(&robot);
        for (k, case) in entry["cases"].as_array().expect("cases").iter().enumerate() {
            let (q, qd, qdd) = (
                joint_vector(&case["q"]),
                joint_vector(&case["qd"]),
                joint_vector(&case["qdd"]),
            );
            let jac = jacobian(&robot, &mut data, &q);
            for link in robot.links() {
                let pose = data
                    .frame(link.frame)
                    .compose(&link.offset)
                    .to_homogeneous();
                let want = matrix(&case["link_poses"][link.name.as_str()]);
                for r in 0..4 {
                    for c in 0..4 {
                        close(
                            &format!("{name} case {k} pose of {}[{r}][{c}]", link.name),
                            pose[(r, c)],
                            want[r][c],
                        );
                    }
                }
                if link.name == tip {
                    let tool = data.tool_frame().to_homogeneous();
                    assert!(
                        (tool - pose).amax() < 1e-15,
                        "{name}: tool frame is the tip link"
                    );
                }
            }
            let want = matrix(&case["tip_jacobian"]);
            for r in 0..6 {
                for c in 0..n {
                    close(
                        &format!("{name} case {k} jacobian[{r}][{c}]"),
                        jac[(r, c)],
                        want[r][c],
                    );
                }
            }
            let m = mass_matrix(&robot, &mut data, &q);
            let want = matrix(&case["mass_matrix"]);
            for r in 0..n {
                for c in 0..n {
                    close(
                        &format!("{name} case {k} M[{r}][{c}]"),
                        m[(r, c)],
                        want[r][c],
                    );
                }
            }
            let g = gravity_torque(&robot, &mut data, &q);
            let c = coriolis_torque(&robot, &mut data, &q, &qd);
            let mut tau = rnea(&robot, &mut data, &q, &qd, &qdd);
            for (i, j) in robot.joints().iter().enumerate() {
                tau[i] -= j.friction_torque(qd[i]);
            }
            for (what, got, key) in [
                ("g", g, "gravity"),
                ("C qd", c, "coriolis"),
                ("tau", tau, "tau"),
            ] {
                let want = vector(&case[key]);
                for i in 0..n {
                    close(&format!("{name} case {k} {what}[{i}]"), got[i], want[i]);
                }
            }
            // Forward dynamics inverts the (friction-included) inverse dynamics.
            let full = rnea(&robot, &mut data, &q, &qd, &qdd);
            let back = forward_dynamics(&robot, &mut data, &q, &qd, &full);
            for i in 0..n {
                assert!(
                    (back[i] - qdd[i]).abs() < 1e-8 * (1.0 + qdd[i].abs()),
                    "{name} case {k} forward dynamics [{i}]: {} vs {}",
                    back[i],
                    qdd[i]
                );
            }
        }
    }
}

/// `<dynamics damping friction>` becomes viscous and Coulomb friction (the
/// values Pinocchio parsed from the same file): τ with friction minus
/// Pinocchio's rigid-body τ is `damping·q̇ + friction·sign(q̇)`.
#[test]
fn urdf_dynamics_element_is_joint_friction() {
    for (robot, entry) in robots() {
        let name = entry["name"].as_str().expect("name");
        let damping = vector(&entry["damping"]);
        let friction = vector(&entry["friction"]);
        let mut data = ModelData::new(&robot);
        for (i, j) in robot.joints().iter().enumerate() {
            assert_eq!(j.viscous_friction, damping[i], "{name} {}", j.name);
            assert_eq!(j.coulomb_friction, friction[i], "{name} {}", j.name);
        }
        for case in entry["cases"].as_array().expect("cases") {
            let (q, qd, qdd) = (
                joint_vector(&case["q"]),
                joint_vector(&case["qd"]),
                joint_vector(&case["qdd"]),
            );
            let tau = rnea(&robot, &mut data, &q, &qd, &qdd);
            let rigid = vector(&case["tau"]);
            for i in 0..robot.dof() {
                let want = damping[i] * qd[i] + friction[i] * qd[i].signum();
                // The difference of two torques: rounding of their size, not of its own.
                let tol = 1e-9 * (want.abs() + rigid[i].abs()) + 1e-12;
                let got = tau[i] - rigid[i];
                assert!(
                    (got - want).abs() <= tol,
                    "{name} friction [{i}]: {got:e} vs {want:e}"
                );
            }
        }
    }
}
