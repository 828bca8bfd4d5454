//! Criterion benchmarks of the hot-path algorithms on the seed arm
//! (`config/robots/seed-arm.toml`) at random states inside its limits.
//! Run: `cargo bench -p microrobot-model --bench model`.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use criterion::{Criterion, criterion_group, criterion_main};
use microrobot_model::{
    JointVector, ModelData, Robot, forward_dynamics, forward_kinematics, jacobian, lagrange_euler,
    mass_matrix, rnea,
};
use std::hint::black_box;
use std::path::Path;

const STATES: usize = 64;

struct State {
    q: JointVector,
    qd: JointVector,
    qdd: JointVector,
}

fn states(robot: &Robot) -> Vec<State> {
    let mut seed = 0x1234_5678_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..STATES)
        .map(|_| {
            let mut s = State {
                q: JointVector::zeros(),
                qd: JointVector::zeros(),
                qdd: JointVector::zeros(),
            };
            for (i, j) in robot.joints().iter().enumerate() {
                let l = &j.limits;
                s.q[i] = l.min + next() * (l.max - l.min);
                s.qd[i] = (2.0 * next() - 1.0) * l.velocity;
                s.qdd[i] = (2.0 * next() - 1.0) * l.acceleration;
            }
            s
        })
        .collect()
}

fn benches(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
    let robot = match Robot::from_file(&path) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    };
    let mut data = ModelData::new(&robot);
    let st = states(&robot);
    let mut k = 0usize;
    let mut next = || {
        k = (k + 1) % STATES;
        &st[k]
    };
    c.bench_function("model/fk", |b| {
        b.iter(|| {
            let s = next();
            forward_kinematics(&robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function("model/jacobian", |b| {
        b.iter(|| {
            let s = next();
            jacobian(&robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function("model/rnea", |b| {
        b.iter(|| {
            let s = next();
            rnea(
                &robot,
                &mut data,
                black_box(&s.q),
                black_box(&s.qd),
                black_box(&s.qdd),
            )
        })
    });
    c.bench_function("model/mass_matrix", |b| {
        b.iter(|| {
            let s = next();
            mass_matrix(&robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function("model/forward_dynamics", |b| {
        b.iter(|| {
            let s = next();
            forward_dynamics(
                &robot,
                &mut data,
                black_box(&s.q),
                black_box(&s.qd),
                black_box(&s.qdd),
            )
        })
    });
    c.bench_function("model/lagrange_euler", |b| {
        b.iter(|| {
            let s = next();
            lagrange_euler::torque(&robot, black_box(&s.q), black_box(&s.qd), black_box(&s.qdd))
        })
    });
}

criterion_group!(model, benches);
criterion_main!(model);
