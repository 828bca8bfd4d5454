//! The hot path allocates nothing: forward kinematics, Jacobian, RNEA (and its
//! gravity/Coriolis variants), CRBA and forward dynamics run under a counting
//! global allocator that counts this thread's allocations.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use microrobot_model::{
    JointVector, ModelData, Robot, coriolis_torque, forward_dynamics, forward_kinematics,
    gravity_torque, jacobian, mass_matrix, nonlinear_effects, rnea,
};
use std::hint::black_box;

#[path = "../../../tests/support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

#[test]
fn hot_path_allocates_nothing() {
    // The DH robots and two URDF robots (placed joints: the general path).
    for file in [
        "config/robots/seed-arm.toml",
        "config/robots/spherical-rrp.toml",
        "config/robots/planar-2r.toml",
        "tests/reference/urdf/panda.toml",
        "tests/reference/urdf/test_arm.toml",
    ] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(file);
        let robot = Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        let mut data = ModelData::new(&robot);
        let mut q = JointVector::zeros();
        let mut qd = JointVector::zeros();
        let mut qdd = JointVector::zeros();
        for i in 0..robot.dof() {
            q[i] = 0.1 * (i as f64 + 1.0);
            qd[i] = -0.2 + 0.1 * i as f64;
            qdd[i] = 0.3 - 0.05 * i as f64;
        }
        let before = allocations();
        // The allocator really counts (guards against a test that cannot fail).
        drop(black_box(vec![1u8; 16]));
        assert_eq!(allocations(), before + 1);
        let before = allocations();
        for _ in 0..10 {
            black_box(forward_kinematics(&robot, &mut data, black_box(&q)));
            black_box(jacobian(&robot, &mut data, black_box(&q)));
            let tau = black_box(rnea(&robot, &mut data, black_box(&q), &qd, &qdd));
            black_box(gravity_torque(&robot, &mut data, &q));
            black_box(coriolis_torque(&robot, &mut data, &q, &qd));
            black_box(nonlinear_effects(&robot, &mut data, &q, &qd));
            black_box(mass_matrix(&robot, &mut data, black_box(&q)));
            black_box(forward_dynamics(&robot, &mut data, &q, &qd, &tau));
        }
        assert_eq!(allocations() - before, 0, "{file}: the hot path allocated");
    }
}
