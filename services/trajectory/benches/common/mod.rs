//! Benchmark problems shared by the criterion bench and the `cpu_time` example.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop, dead_code)]

use microrobot_trajectory::{
    JointVector, KinematicLimits, MotionRequest, MotionState, Profile, Trajectory,
};

/// Seed Table 4 limits (rad, s) for joints 1–6.
fn table4_limits() -> KinematicLimits {
    let big = [135f64, 70.0, 70.0, 135.0, 70.0, 135.0];
    let mut l =
        KinematicLimits::uniform(1.0, 1.0, 1.0, -std::f64::consts::PI, std::f64::consts::PI);
    for (i, v) in big.iter().enumerate() {
        l.velocity[i] = v.to_radians();
        l.acceleration[i] = (v * 80.0 / 135.0).round().to_radians();
        l.jerk[i] = (2.0 * (v * 80.0 / 135.0).round()).to_radians();
    }
    l
}

pub fn table4_request() -> MotionRequest {
    let qi = [-180f64, -90.0, 0.0, -180.0, -90.0, -180.0];
    let qf = [180f64, 90.0, 180.0, 180.0, 90.0, 180.0];
    let mut start = JointVector::zeros();
    let mut target = JointVector::zeros();
    for i in 0..6 {
        start[i] = qi[i].to_radians();
        target[i] = qf[i].to_radians();
    }
    MotionRequest {
        dof: 6,
        start: MotionState::at_rest(start),
        target: MotionState::at_rest(target),
        profile: Profile::Soft { min_duration: None },
        limits: table4_limits(),
    }
}

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Random 6-joint problems from moving states inside the limits (no brake needed).
pub fn random_from_state(n: usize) -> Vec<MotionRequest> {
    let mut rng = Lcg(30303);
    let lim = table4_limits();
    let mut out = Vec::new();
    while out.len() < n {
        let mut req = table4_request();
        for i in 0..6 {
            let (v, a, j) = (lim.velocity[i], lim.acceleration[i], lim.jerk[i]);
            let a0 = (2.0 * rng.next() - 1.0) * a;
            let s = a0 * a0.abs() / (2.0 * j);
            let (lo, hi) = ((-v).max(-v - s), v.min(v - s));
            req.start.q[i] = (2.0 * rng.next() - 1.0) * 2.5;
            req.limits.position_min[i] = -10.0;
            req.limits.position_max[i] = 10.0;
            req.start.qd[i] = lo + rng.next() * (hi - lo);
            req.start.qdd[i] = a0;
            req.target.q[i] = (2.0 * rng.next() - 1.0) * 2.5;
        }
        if Trajectory::plan(&req).is_ok() {
            out.push(req);
        }
    }
    out
}
