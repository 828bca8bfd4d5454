//! Property tests on random placed chains (URDF-style joints: random xyz/rpy
//! origins, random unit axes, revolute and prismatic mixed, SPD inertias,
//! friction, rotor inertia, a tool), and DH chains rewritten as placed chains.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

mod common;

use common::{
    build, build_placed, jv, placed_spec, projected_gradient, robot_spec, scale, state, to_placed,
};
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

// Inverse kinematics of a position target on a general chain, and what the
// solver can promise.
//
// The solver minimises f(q) = ½|e|², e = t − p(q), by Levenberg-Marquardt: a
// local method, which stops where the projected gradient Jᵀe vanishes. With
// e = t − p(q) and ∇²f = JᵀJ − Σₖ eₖ ∇²pₖ, such a stationary point is a local
// minimum whenever the residual is small against the curvature of the reachable
// set p(q). That set folds over itself: for 2 joints it is a surface in R³, and
// for more joints (with prismatic joints stopped at their limits) it can fold
// too. A target on one sheet is also the foot of the perpendicular from another
// sheet passing near it, at distance d = |e| > 0, and when that sheet curves away
// from the target more slowly than a sphere of radius d (d·κ < 1), the foot is a
// strict local minimum with f > 0. No local method escapes it, and restarts
// only help if a seed lands in the solution's basin, which can be any fraction
// of the joint space: on the chain of `two_joint_chain_has_a_spurious_local_minimum`
// below it is 37 % (587 of a 40×40 grid of seeds converge), and all 9 fixed
// attempts of `solve` (the zero seed and 8 restarts) fall in the other basin.
// Over random chains of up to 7 joints, `solve` from the zero seed ends at such
// a minimum in about 1 case in 2000 (96 of 200 000), mostly on 2-4 joints: the
// old property "always converges" failed about one 32-case run in 70.
//
// What holds, and is tested:
// * from a seed near a solution q* the local method converges: f(q*) = 0, so the
//   residual term of ∇²f vanishes and ∇²f = JᵀJ; LM is then (damped)
//   Gauss-Newton, locally quadratically convergent when J has full column rank
//   (n ≤ 3), and for redundant chains (full row rank) to a nearby point of the
//   solution manifold (local error bound: Yamashita-Fukushima, Fan-Yuan). The
//   radius of that neighbourhood scales with σ_min(J) over the curvature of p
//   and has no lower bound over all chains (near-singular configurations shrink
//   it), so the test perturbs each joint by up to 0.01 rad (prismatic: the same
//   fraction of its range over 2π): no failures in 200 000 random cases, where
//   0.05 rad gave 3 (2-joint chains, spurious minima 4-45 µm from the target);
// * from any seed `solve` returns either a converged solution or a stationary
//   point of f over the box of joint limits (a KKT point: the gradient Jᵀe has
//   no component along a joint that is free to move that way), inside the
//   limits, no worse than the seed, with its true residual reported.
//
// The RNG seed is pinned so CI runs the same cases every time; PROPTEST_RNG_SEED
// and PROPTEST_CASES override it to explore.
fn ik_config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x1c_2007),
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(ik_config(32))]

    /// The local guarantee: from a seed within 0.01 rad (per joint, as a
    /// fraction of a full turn of its range) of a solution, the damped
    /// least-squares descent alone, without restarts, converges.
    #[test]
    fn ik_position_converges_from_a_seed_near_a_solution(
        spec in placed_spec(7),
        u in prop::array::uniform8(0.0..1.0f64),
        d in prop::array::uniform8(-1.0..1.0f64),
    ) {
        use microrobot_model::forward_kinematics;
        use microrobot_model::ik::{IkOptions, IkTarget, solve_local};
        let arm = build_placed(&spec);
        let mut data = ModelData::new(&arm);
        let (mut q_true, mut seed) = (JointVector::zeros(), JointVector::zeros());
        for (i, j) in arm.joints().iter().enumerate() {
            let (lo, hi) = (j.limits.min, j.limits.max);
            q_true[i] = lo + (0.05 + 0.9 * u[i]) * (hi - lo);
            seed[i] = q_true[i] + 0.01 * d[i] * (hi - lo) / std::f64::consts::TAU;
        }
        let target = forward_kinematics(&arm, &mut data, &q_true).translation.vector;
        let sol = solve_local(&arm, &mut data, &IkTarget::Position(target), &seed, &IkOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        prop_assert!(sol.converged && sol.position_error_m < 1e-9, "{sol:?}");
        let reached = forward_kinematics(&arm, &mut data, &sol.q).translation.vector;
        prop_assert!((reached - target).norm() < 1e-9);
    }

    /// From the zero seed, with restarts: a reachable target is either reached
    /// or the solver stops at a (bound-constrained) local minimum of the
    /// residual, and says so honestly.
    #[test]
    fn ik_position_from_zero_seed_converges_or_stops_at_a_local_minimum(
        spec in placed_spec(7),
        u in prop::array::uniform8(0.0..1.0f64),
    ) {
        use microrobot_model::forward_kinematics;
        use microrobot_model::ik::{IkOptions, IkTarget, solve};
        let arm = build_placed(&spec);
        let mut data = ModelData::new(&arm);
        let mut q_true = JointVector::zeros();
        for (i, j) in arm.joints().iter().enumerate() {
            q_true[i] = j.limits.min + u[i] * (j.limits.max - j.limits.min);
        }
        let target = forward_kinematics(&arm, &mut data, &q_true).translation.vector;
        let zero = JointVector::zeros();
        let seed_error = (forward_kinematics(&arm, &mut data, &zero).translation.vector - target).norm();
        let sol = solve(&arm, &mut data, &IkTarget::Position(target), &zero, &IkOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        for (i, j) in arm.joints().iter().enumerate() {
            prop_assert!(j.limits.contains(sol.q[i]), "q[{i}] = {}", sol.q[i]);
        }
        let reached = forward_kinematics(&arm, &mut data, &sol.q).translation.vector;
        prop_assert!(((reached - target).norm() - sol.position_error_m).abs() < 1e-12, "{sol:?}");
        prop_assert!(sol.position_error_m <= seed_error, "{sol:?} seed error {seed_error}");
        if sol.converged {
            prop_assert!(sol.position_error_m < 1e-9);
        } else {
            // Observed at most 2e-7 over 200 000 random chains.
            let g = projected_gradient(&arm, &mut data, &sol.q, &target);
            prop_assert!(g < 1e-5, "not a stationary point: projected gradient {g:e}, {sol:?}");
        }
    }
}

/// The chain the old property "converges from the zero seed with 8 restarts"
/// failed on: two revolute joints, a target at q* = (−2.9416, 1.9742). The
/// residual has a strict local minimum 14.8 mm from the target at
/// q ≈ (−2.6968, −3.0730), whose basin holds the zero seed and all 8 restart
/// seeds; from near q* the solver converges.
#[test]
fn two_joint_chain_has_a_spurious_local_minimum() {
    use common::{PlacedJointSpec, PlacedSpec};
    use microrobot_model::forward_kinematics;
    use microrobot_model::ik::{IkOptions, IkTarget, solve, solve_local};
    let joint = |xyz: [f64; 3], rpy: [f64; 3], axis: [f64; 3]| PlacedJointSpec {
        prismatic: false,
        xyz,
        rpy,
        axis,
        mass: 0.05,
        com: [0.0; 3],
        a: [0.0; 9],
        rotor: 0.0,
        viscous: 0.0,
        coulomb: 0.0,
    };
    let arm = build_placed(&PlacedSpec {
        gravity: [0.0; 3],
        joints: vec![
            joint(
                [0.0; 3],
                [0.0; 3],
                [0.6089490376270793, 0.8088305877464584, -0.7338989703159395],
            ),
            joint(
                [0.0, 0.29115444471644936, 0.11147126419415482],
                [1.4192904001318005, -1.5667842791304094, -2.7239147119755853],
                [0.6420885387370977, -0.3321331905110189, 0.565041285709335],
            ),
        ],
        tool: ([0.0, 0.006904980205489654, -0.07364194443383183], [0.0; 3]),
    });
    let mut data = ModelData::new(&arm);
    let pi = std::f64::consts::PI;
    let mut q_true = JointVector::zeros();
    q_true[0] = -pi + 0.031830967788938194 * 2.0 * pi;
    q_true[1] = -pi + 0.8142075721025537 * 2.0 * pi;
    let target = forward_kinematics(&arm, &mut data, &q_true)
        .translation
        .vector;
    let error = |data: &mut ModelData, q: &JointVector| {
        (forward_kinematics(&arm, data, q).translation.vector - target).norm()
    };

    let sol = solve(
        &arm,
        &mut data,
        &IkTarget::Position(target),
        &JointVector::zeros(),
        &IkOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(!sol.converged, "{sol:?}");
    assert!(
        (sol.q[0] + 2.6968).abs() < 1e-3 && (sol.q[1] + 3.0730).abs() < 1e-3,
        "{sol:?}"
    );
    assert!((sol.position_error_m - 0.01477).abs() < 1e-4, "{sol:?}");
    // A stationary point: the residual is normal to the reachable surface ...
    let g = projected_gradient(&arm, &mut data, &sol.q, &target);
    assert!(g < 1e-6, "projected gradient {g:e}");
    // ... and a strict local minimum: every nearby configuration is farther.
    for k in 0..16 {
        let a = k as f64 * pi / 8.0;
        let mut q = sol.q;
        q[0] += 0.02 * a.cos();
        q[1] += 0.02 * a.sin();
        assert!(error(&mut data, &q) > sol.position_error_m, "direction {k}");
    }
    // Every restart seed lies in its basin ...
    for restarts in 0..=8 {
        let s = solve(
            &arm,
            &mut data,
            &IkTarget::Position(target),
            &JointVector::zeros(),
            &IkOptions {
                restarts,
                ..IkOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            !s.converged && (s.q - sol.q).amax() < 1e-3,
            "{restarts} restarts: {s:?}"
        );
    }
    // ... though other seeds reach the target (37 % of a 40×40 grid) ...
    let mut converged = 0;
    for a in 0..40 {
        for b in 0..40 {
            let mut seed = JointVector::zeros();
            seed[0] = -pi + 2.0 * pi * (a as f64 + 0.5) / 40.0;
            seed[1] = -pi + 2.0 * pi * (b as f64 + 0.5) / 40.0;
            let s = solve_local(
                &arm,
                &mut data,
                &IkTarget::Position(target),
                &seed,
                &IkOptions::default(),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            converged += usize::from(s.converged);
        }
    }
    assert!(
        (400..1200).contains(&converged),
        "{converged} of 1600 seeds converge"
    );
    // ... in particular every seed near the solution.
    for k in 0..8 {
        let a = k as f64 * pi / 4.0;
        let mut seed = q_true;
        seed[0] += 0.05 * a.cos();
        seed[1] += 0.05 * a.sin();
        let s = solve_local(
            &arm,
            &mut data,
            &IkTarget::Position(target),
            &seed,
            &IkOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            s.converged && (s.q - q_true).amax() < 1e-6,
            "direction {k}: {s:?}"
        );
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
