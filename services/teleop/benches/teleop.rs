//! Criterion benchmark of one teleoperation cycle (filter, scaling, Cartesian limits,
//! IK, jerk-limited joint update) on the seed arm, the hand moving on a circle with
//! tremor. Run: `cargo bench -p microrobot-teleop --bench teleop`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use microrobot_model::{JointVector, Robot};
use microrobot_teleop::{Hand, TeleopController, TeleopSettings};
use microrobot_trajectory::{KinematicLimits, Sample};
use nalgebra::Vector3;

fn benches(c: &mut Criterion) {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
    let robot = Robot::from_file(&path).expect("seed arm");
    let mut q = JointVector::zeros();
    for (i, v) in [0.0, 30.0, 60.0, 0.0, 30.0, 0.0f64].iter().enumerate() {
        q[i] = v.to_radians();
    }
    let start = Sample {
        q,
        ..Default::default()
    };
    let limits = KinematicLimits::from_robot(&robot);
    let mut ctl = TeleopController::new(&robot, TeleopSettings::default(), &limits, 1e-3, start)
        .expect("controller");
    let mut k = 0u64;
    c.bench_function("teleop/step", |b| {
        b.iter(|| {
            k += 1;
            let t = k as f64 * 1e-3;
            let w = 2.0 * std::f64::consts::PI;
            let tremor = 2e-4 * (w * 10.0 * t).sin();
            let hand = Hand {
                position: Vector3::new(
                    3e-3 * (w * 0.5 * t).sin() + tremor,
                    3e-3 * (w * 0.5 * t).cos() - 3e-3,
                    tremor,
                ),
                clutch: true,
            };
            black_box(ctl.step(Some(black_box(&hand))))
        })
    });
}

criterion_group!(teleop, benches);
criterion_main!(teleop);
