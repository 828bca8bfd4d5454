//! What the model's examples and benchmarks share: the seed arm and the same 64 random
//! states inside its limits (a fixed xorshift sequence, so every tool measures the same
//! calls).

use microrobot_model::{JointVector, Robot};

/// The seed arm (`config/robots/seed-arm.toml`); exits with the loader's message if the
/// file is bad.
pub fn seed_arm() -> Robot {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
    match Robot::from_file(&path) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}

/// The Panda from URDF (`tests/reference/urdf/panda.toml`: tip at the hand's TCP, fingers
/// locked); exits with the loader's message if the file is bad.
#[allow(dead_code)] // the benchmarks use it, the examples only the seed arm
pub fn panda() -> Robot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference/urdf/panda.toml");
    match Robot::from_file(&path) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}

/// `n` states `[q, qd, qdd]`, uniform within the position limits and ± the velocity and
/// acceleration limits of `robot` (± 5 rad/s² where the robot file gives none).
pub fn random_states(robot: &Robot, n: usize) -> Vec<[JointVector; 3]> {
    let mut seed = 0x1234_5678_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let mut s = [JointVector::zeros(); 3];
            for (i, j) in robot.joints().iter().enumerate() {
                let l = &j.limits;
                s[0][i] = l.min + next() * (l.max - l.min);
                s[1][i] = (2.0 * next() - 1.0) * l.velocity;
                let acc = if l.acceleration.is_finite() {
                    l.acceleration
                } else {
                    5.0
                };
                s[2][i] = (2.0 * next() - 1.0) * acc;
            }
            s
        })
        .collect()
}
