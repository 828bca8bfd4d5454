//! Property tests on random placed chains (URDF-style joints: random xyz/rpy
//! origins, random unit axes, revolute and prismatic mixed, SPD inertias,
//! friction, rotor inertia, a tool), and DH chains rewritten as placed chains.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

mod common;

use common::{build, build_placed, jv, placed_spec, robot_spec, scale, state, to_placed};
use microrobot_model::{
    JointVector, ModelData, Robot, forward_dynamics, gravity_torque, jacobian, lagrange_euler,
    mass_matrix, rnea, tool_pose,
};
use nalgebra::DMatrix;
use proptest::prelude::*;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 64,
        ..ProptestConfig::default()
    }
}

fn condition(robot: &Robot, data: &mut ModelData, q: &JointVector) -> f64 {
    let m = mass_matrix(robot, data, q);
    let n = robot.dof();
    let e = nalgebra::SymmetricEigen::new(DMatrix::from_fn(n, n, |r, c| m[(r, c)])).eigenvalues;
    e.max() / e.min()
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mass_matrix_is_symmetric_positive_definite(spec in placed_spec(8), (q, _, _) in state()) {
        let robot = build_placed(&spec);
        prop_assert!(robot.is_placed());
        let mut data = ModelData::new(&robot);
        let n = robot.dof();
        let m = mass_matrix(&robot, &mut data, &jv(&robot, &q, true));
        let block = DMatrix::from_fn(n, n, |r, c| m[(r, c)]);
        let big = block.abs().max();
        prop_assert!((&block - block.transpose()).abs().max() <= 1e-12 * big);
        let eig = nalgebra::SymmetricEigen::new(block).eigenvalues;
        prop_assert!(eig.min() > 0.0, "eigenvalues {eig}");
        for r in 0..8 {
            for c in 0..8 {
                if r >= n || c >= n {
                    prop_assert_eq!(m[(r, c)], 0.0);
                }
            }
        }
    }

    #[test]
    fn forward_dynamics_inverts_inverse_dynamics(spec in placed_spec(8), (q, qd, qdd) in state()) {
        let robot = build_placed(&spec);
        let mut data = ModelData::new(&robot);
        let (q, qd, qdd) = (jv(&robot, &q, true), jv(&robot, &qd, false), jv(&robot, &qdd, false));
        let tau = rnea(&robot, &mut data, &q, &qd, &qdd);
        let back = forward_dynamics(&robot, &mut data, &q, &qd, &tau);
        let cond = condition(&robot, &mut data, &q);
        let tol = 1e-13 * cond * (1.0 + scale(&qdd, robot.dof()));
        prop_assert!((back - qdd).amax() <= tol.max(1e-10), "qdd {qdd} back {back} cond {cond:e}");
    }

    #[test]
    fn rnea_at_rest_is_gravity_and_mass_columns_are_rnea_differences(
        spec in placed_spec(8), (q, _, _) in state()
    ) {
        let robot = build_placed(&spec);
        let mut data = ModelData::new(&robot);
        let q = jv(&robot, &q, true);
        let zero = JointVector::zeros();
        let g = rnea(&robot, &mut data, &q, &zero, &zero);
        let gt = gravity_torque(&robot, &mut data, &q);
        prop_assert!((g - gt).amax() <= 1e-12 * (1.0 + g.amax()), "rnea {g} gravity {gt}");
        let m = mass_matrix(&robot, &mut data, &q);
        for j in 0..robot.dof() {
            let mut e = JointVector::zeros();
            e[j] = 1.0;
            let col = rnea(&robot, &mut data, &q, &zero, &e) - g;
            let tol = 1e-10 * (1.0 + m.column(j).amax() + g.amax());
            prop_assert!((col - m.column(j)).amax() <= tol, "column {j}: {col} vs {}", m.column(j));
        }
    }

    #[test]
    fn jacobian_equals_finite_differences_of_fk(spec in placed_spec(8), (q, _, _) in state()) {
        let robot = build_placed(&spec);
        let mut data = ModelData::new(&robot);
        let q = jv(&robot, &q, true);
        let jac = jacobian(&robot, &mut data, &q);
        let h = 1e-6;
        for j in 0..robot.dof() {
            let (mut qp, mut qm) = (q, q);
            qp[j] += h;
            qm[j] -= h;
            let pp = tool_pose(&robot, &mut data, &qp);
            let pm = tool_pose(&robot, &mut data, &qm);
            let v = (pp.translation - pm.translation) / (2.0 * h);
            let dr = pp.rotation * pm.rotation.transpose();
            let w = nalgebra::Vector3::new(dr[(2, 1)] - dr[(1, 2)], dr[(0, 2)] - dr[(2, 0)], dr[(1, 0)] - dr[(0, 1)])
                / (4.0 * h);
            for r in 0..3 {
                prop_assert!((jac[(r, j)] - v[r]).abs() < 1e-6, "linear [{r}][{j}]: {} vs {}", jac[(r, j)], v[r]);
                prop_assert!((jac[(r + 3, j)] - w[r]).abs() < 1e-6, "angular [{r}][{j}]: {} vs {}", jac[(r + 3, j)], w[r]);
            }
        }
        for c in robot.dof()..8 {
            prop_assert!(jac.column(c).iter().all(|x| *x == 0.0));
        }
    }

    /// The literal Lagrange-Euler equations (4×4 matrices, `Q = X G X⁻¹` for a
    /// placed joint) agree with Newton-Euler on placed chains.
    #[test]
    fn lagrange_euler_equals_newton_euler(spec in placed_spec(6), (q, qd, qdd) in state()) {
        let robot = build_placed(&spec);
        let mut data = ModelData::new(&robot);
        let (q, qd, qdd) = (jv(&robot, &q, true), jv(&robot, &qd, false), jv(&robot, &qdd, false));
        let ne = rnea(&robot, &mut data, &q, &qd, &qdd);
        let le = lagrange_euler::torque(&robot, &q, &qd, &qdd);
        prop_assert!((ne - le).amax() <= 1e-9 * (1.0 + ne.amax()), "NE {ne} LE {le}");
        let m = mass_matrix(&robot, &mut data, &q);
        let m_le = lagrange_euler::mass_matrix(&robot, &q);
        prop_assert!((m - m_le).amax() <= 1e-9 * (1.0 + m.amax()));
    }

    /// A DH chain and the same chain with placed joints (the general path) give
    /// the same tool pose, Jacobian, mass matrix and torques.
    #[test]
    fn dh_chain_rewritten_as_placed_joints_agrees(spec in robot_spec(8), (q, qd, qdd) in state()) {
        let dh = build(&spec);
        let placed = to_placed(&dh);
        prop_assert!(!dh.is_placed() && placed.is_placed());
        let (mut d1, mut d2) = (ModelData::new(&dh), ModelData::new(&placed));
        let (q, qd, qdd) = (jv(&dh, &q, true), jv(&dh, &qd, false), jv(&dh, &qdd, false));
        let close = |a: &[f64], b: &[f64], what: &str| -> Result<(), TestCaseError> {
            let big = a.iter().fold(1.0_f64, |m, x| m.max(x.abs()));
            for (x, y) in a.iter().zip(b) {
                prop_assert!((x - y).abs() <= 1e-9 * big, "{what}: {a:?} vs {b:?}");
            }
            Ok(())
        };
        let p1 = tool_pose(&dh, &mut d1, &q).to_homogeneous();
        let p2 = tool_pose(&placed, &mut d2, &q).to_homogeneous();
        close(p1.as_slice(), p2.as_slice(), "tool pose")?;
        close(jacobian(&dh, &mut d1, &q).as_slice(), jacobian(&placed, &mut d2, &q).as_slice(), "jacobian")?;
        close(mass_matrix(&dh, &mut d1, &q).as_slice(), mass_matrix(&placed, &mut d2, &q).as_slice(), "mass matrix")?;
        close(
            rnea(&dh, &mut d1, &q, &qd, &qdd).as_slice(),
            rnea(&placed, &mut d2, &q, &qd, &qdd).as_slice(),
            "rnea",
        )?;
        // Shared scratch: the sine/cosine cache must not leak between the paths.
        let mut shared = ModelData::new(&dh);
        let a = rnea(&dh, &mut shared, &q, &qd, &qdd);
        let b = rnea(&placed, &mut shared, &q, &qd, &qdd);
        close(a.as_slice(), b.as_slice(), "rnea, shared scratch")?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Inverse kinematics on placed chains: the tool position of a random
    /// configuration is found again from the zero seed.
    #[test]
    fn ik_position_round_trip_on_placed_chains(spec in placed_spec(7), u in prop::array::uniform8(0.0..1.0f64)) {
        use microrobot_model::forward_kinematics;
        use microrobot_model::ik::{IkOptions, IkTarget, solve};
        let arm = build_placed(&spec);
        let mut data = ModelData::new(&arm);
        let mut q_true = JointVector::zeros();
        for (i, j) in arm.joints().iter().enumerate() {
            q_true[i] = j.limits.min + u[i] * (j.limits.max - j.limits.min);
        }
        let target = forward_kinematics(&arm, &mut data, &q_true).translation.vector;
        let sol = solve(&arm, &mut data, &IkTarget::Position(target), &JointVector::zeros(), &IkOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        prop_assert!(sol.converged, "{sol:?}");
        prop_assert!(sol.position_error_m < 1e-9);
        let reached = forward_kinematics(&arm, &mut data, &sol.q).translation.vector;
        prop_assert!((reached - target).norm() < 1e-9);
    }
}

/// The planar 2R arm with placed joints sweeps the same annulus as the DH file.
#[test]
fn placed_planar_2r_sweeps_the_annulus() {
    use microrobot_model::workspace::{WorkspaceOptions, reachable_workspace};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots");
    let arm =
        to_placed(&Robot::from_file(&dir.join("planar-2r.toml")).unwrap_or_else(|e| panic!("{e}")));
    assert!(arm.is_placed());
    let (l1, l2) = (0.3_f64, 0.2_f64);
    let exact = std::f64::consts::PI * ((l1 + l2).powi(2) - (l1 - l2).powi(2));
    let ws = reachable_workspace(
        &arm,
        &WorkspaceOptions {
            samples: 400_000,
            voxel_size_m: 0.005,
            ..Default::default()
        },
        &|_| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let rel = (ws.area_xy_m2 - exact) / exact;
    assert!(rel.abs() < 0.03, "area {} vs {exact}", ws.area_xy_m2);
    for p in &ws.points {
        let r = (p.x * p.x + p.y * p.y).sqrt();
        assert!((l1 - l2 - 1e-12..=l1 + l2 + 1e-12).contains(&r) && p.z.abs() < 1e-12);
    }
}
