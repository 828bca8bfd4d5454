//! The seed arm against `tests/reference/arm_reference.json` (50 cases computed
//! by Pinocchio and cross-checked with the Robotics Toolbox): every quantity, both
//! dynamics paths, 1e-9 relative with a 1e-12 absolute floor; and the parsed
//! `config/robots/seed-arm.toml` against the reference's `model` parameters.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use microrobot_model::{
    JointVector, MassMatrix, ModelData, Robot, coriolis_torque, gravity_torque, jacobian,
    lagrange_euler, mass_matrix, rnea, tool_pose,
};
use serde_json::Value;
use std::path::Path;

const REFERENCE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/reference/arm_reference.json"
);
const SEED_ARM: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../config/robots/seed-arm.toml"
);

fn reference() -> Value {
    let text = std::fs::read_to_string(REFERENCE).expect("reference file readable");
    serde_json::from_str(&text).expect("reference is JSON")
}

fn seed_arm() -> Robot {
    Robot::from_file(Path::new(SEED_ARM)).unwrap_or_else(|e| panic!("{e}"))
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
fn close(what: &str, case: usize, got: f64, want: f64) {
    let tol = (1e-9 * want.abs()).max(1e-12);
    assert!(
        (got - want).abs() <= tol,
        "case {case} {what}: got {got:e}, reference {want:e} (diff {:e} > {tol:e})",
        (got - want).abs()
    );
}

fn check_vector(what: &str, case: usize, got: &JointVector, want: &[f64]) {
    for (i, w) in want.iter().enumerate() {
        close(&format!("{what}[{i}]"), case, got[i], *w);
    }
    for i in want.len()..got.len() {
        assert_eq!(got[i], 0.0, "case {case} {what}[{i}] beyond dof must be 0");
    }
}

fn check_mass(what: &str, case: usize, got: &MassMatrix, want: &[Vec<f64>]) {
    let n = want.len();
    for r in 0..got.nrows() {
        for c in 0..got.ncols() {
            if r < n && c < n {
                close(&format!("{what}[{r}][{c}]"), case, got[(r, c)], want[r][c]);
            } else {
                assert_eq!(
                    got[(r, c)],
                    0.0,
                    "case {case} {what}[{r}][{c}] outside dof must be 0"
                );
            }
        }
    }
}

#[test]
fn newton_euler_path_matches_every_reference_case() {
    let robot = seed_arm();
    let mut data = ModelData::new(&robot);
    let refs = reference();
    let cases = refs["cases"].as_array().expect("cases");
    assert_eq!(cases.len(), 50);
    for (k, case) in cases.iter().enumerate() {
        let (q, qd, qdd) = (
            joint_vector(&case["q"]),
            joint_vector(&case["qd"]),
            joint_vector(&case["qdd"]),
        );
        let fk = tool_pose(&robot, &mut data, &q).to_homogeneous();
        for (r, row) in matrix(&case["fk"]).iter().enumerate() {
            for (c, want) in row.iter().enumerate() {
                close(&format!("fk[{r}][{c}]"), k, fk[(r, c)], *want);
            }
        }
        let iso = microrobot_model::forward_kinematics(&robot, &mut data, &q).to_homogeneous();
        for (r, row) in matrix(&case["fk"]).iter().enumerate() {
            for (c, want) in row.iter().enumerate() {
                // The quaternion round trip of the Isometry3 costs a few ulp.
                assert!(
                    (iso[(r, c)] - want).abs() < 1e-12,
                    "case {k} isometry fk[{r}][{c}]"
                );
            }
        }
        let jac = jacobian(&robot, &mut data, &q);
        for (r, row) in matrix(&case["jacobian"]).iter().enumerate() {
            for (c, want) in row.iter().enumerate() {
                close(&format!("jacobian[{r}][{c}]"), k, jac[(r, c)], *want);
            }
        }
        check_mass(
            "mass_matrix",
            k,
            &mass_matrix(&robot, &mut data, &q),
            &matrix(&case["mass_matrix"]),
        );
        check_vector(
            "gravity_torque",
            k,
            &gravity_torque(&robot, &mut data, &q),
            &vector(&case["gravity_torque"]),
        );
        check_vector(
            "coriolis_torque",
            k,
            &coriolis_torque(&robot, &mut data, &q, &qd),
            &vector(&case["coriolis_torque"]),
        );
        check_vector(
            "tau",
            k,
            &rnea(&robot, &mut data, &q, &qd, &qdd),
            &vector(&case["tau"]),
        );
    }
}

#[test]
fn lagrange_euler_path_matches_every_reference_case() {
    let robot = seed_arm();
    let refs = reference();
    let cases = refs["cases"].as_array().expect("cases");
    for (k, case) in cases.iter().enumerate() {
        let (q, qd, qdd) = (
            joint_vector(&case["q"]),
            joint_vector(&case["qd"]),
            joint_vector(&case["qdd"]),
        );
        check_mass(
            "LE mass_matrix",
            k,
            &lagrange_euler::mass_matrix(&robot, &q),
            &matrix(&case["mass_matrix"]),
        );
        check_vector(
            "LE gravity_torque",
            k,
            &lagrange_euler::gravity(&robot, &q),
            &vector(&case["gravity_torque"]),
        );
        check_vector(
            "LE coriolis_torque",
            k,
            &lagrange_euler::coriolis(&robot, &q, &qd),
            &vector(&case["coriolis_torque"]),
        );
        check_vector(
            "LE tau",
            k,
            &lagrange_euler::torque(&robot, &q, &qd, &qdd),
            &vector(&case["tau"]),
        );
    }
}

#[test]
fn seed_arm_file_equals_the_reference_model() {
    let robot = seed_arm();
    let refs = reference();
    let m = &refs["model"];
    assert_eq!(robot.name(), "seed-arm");
    assert_eq!(robot.dof(), 6);
    let g = vector(&m["gravity"]["vector"]);
    for i in 0..3 {
        close("gravity", 0, robot.gravity()[i], g[i]);
    }
    let dh = m["dh_table"].as_array().expect("dh_table");
    for (i, joint) in robot.joints().iter().enumerate() {
        let row = &dh[i];
        assert_eq!(joint.kind, microrobot_model::JointKind::Revolute);
        close("theta offset", i, joint.dh.theta, 0.0);
        close("d", i, joint.dh.d, num(&row["d_m"]));
        close("a", i, joint.dh.a, num(&row["a_m"]));
        close("alpha", i, joint.dh.alpha, num(&row["alpha_rad"]));
        close("mass", i, joint.link.mass, num(&m["link_mass_kg"][i]));
        let com = vector(&m["com_in_link_frame_m"][i]);
        let inertia = matrix(&m["inertia_about_com_in_link_frame_kgm2"][i]);
        for r in 0..3 {
            close("com", i, joint.link.com[r], com[r]);
            for c in 0..3 {
                close("inertia", i, joint.link.inertia[(r, c)], inertia[r][c]);
            }
        }
        close(
            "rotor inertia",
            i,
            joint.rotor_inertia,
            num(&m["actuator_inertia_kgm2"][i]),
        );
        let l = &joint.limits;
        close("min", i, l.min, num(&m["joint_limits_rad"]["min"][i]));
        close("max", i, l.max, num(&m["joint_limits_rad"]["max"][i]));
        close("vmax", i, l.velocity, num(&m["vmax_radps"][i]));
        close("amax", i, l.acceleration, num(&m["amax_radps2"][i]));
        close("jmax", i, l.jerk, num(&m["jmax_radps3"][i]));
        close("torque limit", i, l.effort, 50.0);
        assert_eq!(joint.gear_ratio, 1.0);
        assert_eq!(joint.viscous_friction, 0.0);
        assert_eq!(joint.coulomb_friction, 0.0);
    }
    assert!(robot.payload().is_none());
    assert_eq!(*robot.tool(), microrobot_model::Pose::IDENTITY);
}
