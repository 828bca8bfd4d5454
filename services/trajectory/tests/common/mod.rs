//! Shared helpers for the integration tests.
#![allow(dead_code)]

use microrobot_trajectory::{JointVector, KinematicLimits, MotionRequest, MotionState, Profile};
use serde_json::Value;

pub fn load(name: &str) -> Value {
    let path = format!(
        "{}/../../tests/reference/{}",
        env!("CARGO_MANIFEST_DIR"),
        name
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).expect("reference JSON parses")
}

pub fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

pub fn fs(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(f).collect()
}

pub fn jv(x: &[f64]) -> JointVector {
    let mut v = JointVector::zeros();
    for (i, &xi) in x.iter().enumerate() {
        v[i] = xi;
    }
    v
}

pub fn limits(v: &[f64], a: &[f64], j: &[f64], range: f64) -> KinematicLimits {
    KinematicLimits {
        velocity: jv(v),
        acceleration: jv(a),
        jerk: jv(j),
        position_min: JointVector::repeat(-range),
        position_max: JointVector::repeat(range),
    }
}

pub fn soft_request(
    q0: &[f64],
    v0: &[f64],
    a0: &[f64],
    q1: &[f64],
    lim: KinematicLimits,
) -> MotionRequest {
    MotionRequest {
        dof: q0.len(),
        start: MotionState {
            q: jv(q0),
            qd: jv(v0),
            qdd: jv(a0),
        },
        target: MotionState::at_rest(jv(q1)),
        profile: Profile::Soft { min_duration: None },
        limits: lim,
    }
}

pub fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

#[track_caller]
pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!(
        close(a, b, tol),
        "{what}: got {a}, expected {b} (diff {:e})",
        a - b
    );
}
