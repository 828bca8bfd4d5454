//! Best-case ns per call of the hot-path algorithms on the seed arm: the minimum
//! over many short batches (256 calls each; 4 for Lagrange-Euler), which filters out the time a shared,
//! loaded machine spends on other processes. Complements the criterion means.
//! Run: `cargo run --release -p microrobot-model --example hot_path_min`.

use microrobot_model::{
    JointVector, ModelData, forward_dynamics, forward_kinematics, jacobian, lagrange_euler,
    mass_matrix, rnea,
};
use std::hint::black_box;

mod common;
use std::time::Instant;

fn main() {
    let robot = common::seed_arm();
    let mut data = ModelData::new(&robot);
    let states = common::random_states(&robot, 64);
    let report =
        |name: &str, batches: usize, calls: usize, f: &mut dyn FnMut(&[JointVector; 3])| {
            let mut best = f64::INFINITY;
            for _ in 0..batches {
                let t0 = Instant::now();
                for k in 0..calls {
                    f(black_box(&states[k & 63]));
                }
                best = best.min(t0.elapsed().as_nanos() as f64 / calls as f64);
            }
            println!("{name:24} {best:9.1} ns");
        };
    report("model/fk", 2000, 256, &mut |s| {
        black_box(forward_kinematics(&robot, &mut data, &s[0]));
    });
    report("model/jacobian", 2000, 256, &mut |s| {
        black_box(jacobian(&robot, &mut data, &s[0]));
    });
    report("model/rnea", 2000, 256, &mut |s| {
        black_box(rnea(&robot, &mut data, &s[0], &s[1], &s[2]));
    });
    report("model/mass_matrix", 2000, 256, &mut |s| {
        black_box(mass_matrix(&robot, &mut data, &s[0]));
    });
    report("model/forward_dynamics", 2000, 256, &mut |s| {
        black_box(forward_dynamics(&robot, &mut data, &s[0], &s[1], &s[2]));
    });
    report("model/lagrange_euler", 300, 4, &mut |s| {
        black_box(lagrange_euler::torque(&robot, &s[0], &s[1], &s[2]));
    });
}
