//! The four methods × final times: planning with the trajectory library, sampling,
//! inverse dynamics (RNEA) split into inertial, Coriolis/centrifugal and gravity
//! parts, and the per-case statistics of the comparison table.

use anyhow::{Result, anyhow};
use microrobot_model::{JointKind, ModelData, Robot, coriolis_torque, gravity_torque, rnea};
use microrobot_trajectory::{
    JointVector, KinematicLimits, MotionRequest, MotionState, Peaks, Profile, Trajectory,
};

use super::motion::StudyMotion;

/// Relative tolerance when comparing a peak with its limit.
pub const LIMIT_TOL: f64 = 1e-9;

/// A trajectory method of the seed (section 3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Third-order polynomial (3.2.1).
    Cubic,
    /// Fifth-order polynomial with the program's boundary accelerations (3.2.2).
    Quintic,
    /// Linear segment with parabolic blends, cruise velocity 1.5·(θf − θi)/tf (3.2.3).
    Lspb,
    /// Jerk-limited soft motion stretched to the final time (3.2.4).
    Soft,
}

impl Method {
    /// All four, in the seed's order.
    pub const ALL: [Method; 4] = [Method::Cubic, Method::Quintic, Method::Lspb, Method::Soft];

    /// File-name key.
    pub fn key(self) -> &'static str {
        match self {
            Method::Cubic => "cubic",
            Method::Quintic => "quintic",
            Method::Lspb => "lspb",
            Method::Soft => "soft",
        }
    }

    /// Human-readable name.
    pub fn title(self) -> &'static str {
        match self {
            Method::Cubic => "Cubic (3rd-order polynomial)",
            Method::Quintic => "Quintic (5th-order polynomial)",
            Method::Lspb => "LSPB (linear segment, parabolic blends)",
            Method::Soft => "Soft motion (jerk-limited, stretched)",
        }
    }

    /// Whether the method can bound jerk (cubic and LSPB jump in acceleration).
    pub fn honours_jerk(self) -> bool {
        matches!(self, Method::Quintic | Method::Soft)
    }

    /// The seed's figure numbers for this method (joint-1 time comparison, its
    /// torque, all joints' kinematics, torque history).
    pub fn seed_figures(self) -> &'static str {
        match self {
            Method::Cubic => "Figures 19, 20, 21, 31",
            Method::Quintic => "Figures 22, 23, 24, 32",
            Method::Lspb => "Figures 25, 26, 27, 33",
            Method::Soft => "Figures 28, 29, 30, 34",
        }
    }
}

/// Kinematic limits of `robot` for planning; position limits widened so the
/// library plans every case (the study reports position violations itself).
pub fn planning_limits(robot: &Robot) -> KinematicLimits {
    let mut l = KinematicLimits::uniform(1.0, 1.0, 1.0, -1.0e6, 1.0e6);
    for (i, j) in robot.joints().iter().enumerate() {
        l.velocity[i] = j.limits.velocity;
        l.acceleration[i] = j.limits.acceleration;
        l.jerk[i] = j.limits.jerk;
    }
    l
}

/// The planning problem of `method` at final time `tf`.
pub fn request(robot: &Robot, motion: &StudyMotion, method: Method, tf: f64) -> MotionRequest {
    let quintic = method == Method::Quintic;
    let start = MotionState {
        q: motion.start,
        qd: JointVector::zeros(),
        qdd: if quintic {
            motion.start_acc
        } else {
            JointVector::zeros()
        },
    };
    let target = MotionState {
        q: motion.target,
        qd: JointVector::zeros(),
        qdd: if quintic {
            motion.target_acc
        } else {
            JointVector::zeros()
        },
    };
    let profile = match method {
        Method::Cubic => Profile::Cubic { duration: tf },
        Method::Quintic => Profile::Quintic { duration: tf },
        Method::Lspb => Profile::Lspb {
            duration: tf,
            cruise_velocity: None,
        },
        Method::Soft => Profile::Soft {
            min_duration: Some(tf),
        },
    };
    MotionRequest {
        dof: robot.dof(),
        start,
        target,
        profile,
        limits: planning_limits(robot),
    }
}

/// Plans `method` at `tf`; errors say which case failed.
pub fn plan(robot: &Robot, motion: &StudyMotion, method: Method, tf: f64) -> Result<Trajectory> {
    Trajectory::plan(&request(robot, motion, method, tf))
        .map_err(|e| anyhow!("{} at tf = {tf} s cannot be planned: {e}", method.key()))
}

/// One limit exceeded in one case.
#[derive(Debug, Clone, PartialEq)]
pub struct Violation {
    /// Joint index (0-based).
    pub joint: usize,
    /// "position", "velocity", "acceleration", "jerk" or "torque".
    pub quantity: &'static str,
    /// Peak reached (SI; for position the distance outside the range).
    pub value: f64,
    /// The limit (SI).
    pub limit: f64,
}

/// Sampled histories and statistics of one method at one final time.
#[derive(Debug, Clone)]
pub struct Case {
    /// Method.
    pub method: Method,
    /// Requested final time (s).
    pub tf: f64,
    /// Actual duration (s) (soft motion: max(tf, its minimum)).
    pub duration: f64,
    /// Sample times (s), uniform on [0, duration].
    pub t: Vec<f64>,
    /// Positions, velocities, accelerations, jerks (SI: rad… or m… per joint type).
    pub q: Vec<JointVector>,
    /// Velocities.
    pub qd: Vec<JointVector>,
    /// Accelerations.
    pub qdd: Vec<JointVector>,
    /// Jerks.
    pub jerk: Vec<JointVector>,
    /// Joint torques (N·m) or forces (N) by inverse dynamics.
    pub tau: Vec<JointVector>,
    /// Exact kinematic peaks from the library.
    pub peaks: Peaks,
    /// Statistics.
    pub stats: CaseStats,
}

/// The comparison-table row of one case.
#[derive(Debug, Clone, Default)]
pub struct CaseStats {
    /// max |τ| per joint (N·m, or N for a prismatic joint).
    pub peak_torque: JointVector,
    /// RMS τ per joint over [0, duration] (N·m or N).
    pub rms_torque: JointVector,
    /// Largest jump of acceleration per joint (rad/s² or m/s²; 0 below numerical
    /// noise), including the jumps from and to rest at the ends (an unbounded jerk).
    pub acc_jump: JointVector,
    /// Σ_i ∫ |τ_i q̇_i| dt (J).
    pub energy: f64,
    /// Limits exceeded.
    pub violations: Vec<Violation>,
    /// Torque-rate sign changes per joint (the seed's "shootings").
    pub shootings: Vec<usize>,
    /// RMS over time of the norm over the revolute joints (`[0]`, N·m) and over the
    /// prismatic joints (`[1]`, N) of the inertial (incl. friction),
    /// Coriolis/centrifugal and gravity parts of the effort.
    pub rms_parts: [[f64; 3]; 2],
    /// Velocity sign changes of each joint (0 = monotonic motion).
    pub reversals: Vec<usize>,
}

/// Names of the torque parts in [`CaseStats::rms_parts`].
pub const PARTS: [&str; 3] = ["inertial", "Coriolis/centrifugal", "gravity"];

/// Plans, samples (`samples` intervals) and evaluates one case.
pub fn run_case(
    robot: &Robot,
    motion: &StudyMotion,
    method: Method,
    tf: f64,
    samples: usize,
) -> Result<Case> {
    let traj = plan(robot, motion, method, tf)?;
    let dof = robot.dof();
    let n = samples.max(2);
    let duration = traj.duration();
    let mut data = ModelData::new(robot);
    let mut c = Case {
        method,
        tf,
        duration,
        t: Vec::with_capacity(n + 1),
        q: Vec::with_capacity(n + 1),
        qd: Vec::with_capacity(n + 1),
        qdd: Vec::with_capacity(n + 1),
        jerk: Vec::with_capacity(n + 1),
        tau: Vec::with_capacity(n + 1),
        peaks: traj.peaks(),
        stats: CaseStats::default(),
    };
    let mut parts_sq = [[0.0; 3]; 2];
    let of_kind = |kind: JointKind, v: &JointVector| {
        (0..dof)
            .filter(|&i| robot.joints()[i].kind == kind)
            .map(|i| v[i] * v[i])
            .sum::<f64>()
    };
    for k in 0..=n {
        let t = duration * k as f64 / n as f64;
        let s = traj.sample(t);
        let tau = rnea(robot, &mut data, &s.q, &s.qd, &s.qdd);
        let g = gravity_torque(robot, &mut data, &s.q);
        let cor = coriolis_torque(robot, &mut data, &s.q, &s.qd);
        let inertial = tau - g - cor;
        let w = if k == 0 || k == n { 0.5 } else { 1.0 };
        for (sq, kind) in parts_sq
            .iter_mut()
            .zip([JointKind::Revolute, JointKind::Prismatic])
        {
            for (p, v) in sq.iter_mut().zip([inertial, cor, g]) {
                *p += w * of_kind(kind, &v);
            }
        }
        c.t.push(t);
        c.q.push(s.q);
        c.qd.push(s.qd);
        c.qdd.push(s.qdd);
        c.jerk.push(s.jerk);
        c.tau.push(tau);
    }
    let mut st = CaseStats {
        rms_parts: parts_sq.map(|sq| sq.map(|p| (p / n as f64).sqrt())),
        ..CaseStats::default()
    };
    let dt = duration / n as f64;
    for i in 0..dof {
        let lim = &robot.joints()[i].limits;
        let tau_i: Vec<f64> = c.tau.iter().map(|v| v[i]).collect();
        st.peak_torque[i] = tau_i.iter().fold(0.0, |m, x| m.max(x.abs()));
        let mut sq = 0.0;
        let mut energy = 0.0;
        for (k, (t, qd)) in tau_i.iter().zip(&c.qd).enumerate() {
            let w = if k == 0 || k == n { 0.5 } else { 1.0 };
            sq += w * t * t;
            energy += w * (t * qd[i]).abs();
        }
        st.rms_torque[i] = (sq / n as f64).sqrt();
        st.energy += energy * dt;
        st.shootings.push(sign_changes(&tau_i, true));
        let qd_i: Vec<f64> = c.qd.iter().map(|v| v[i]).collect();
        st.reversals.push(sign_changes(&qd_i, false));
        // Acceleration jumps: from rest into the first sample, between samples
        // beyond what the in-piece jerk explains, and into rest after the end.
        let a: Vec<f64> = c.qdd.iter().map(|v| v[i]).collect();
        let mut jump = a[0].abs().max(a[n].abs());
        for k in 0..n {
            let step = (a[k + 1] - a[k]).abs() - c.peaks.jerk[i] * dt;
            jump = jump.max(step);
        }
        if jump > 1e-9 * lim.acceleration {
            st.acc_jump[i] = jump;
        }
        let peaks = &c.peaks;
        let tol = |l: f64| l * (1.0 + LIMIT_TOL);
        let over_lo = lim.min - peaks.position_min[i];
        let over_hi = peaks.position_max[i] - lim.max;
        let pos_tol = LIMIT_TOL * (lim.max - lim.min).abs().max(1.0);
        if over_lo.max(over_hi) > pos_tol {
            st.violations.push(Violation {
                joint: i,
                quantity: "position",
                value: over_lo.max(over_hi),
                limit: if over_lo > over_hi { lim.min } else { lim.max },
            });
        }
        let mut checks = vec![
            ("velocity", peaks.velocity[i], lim.velocity),
            ("acceleration", peaks.acceleration[i], lim.acceleration),
            ("torque", st.peak_torque[i], lim.effort),
        ];
        if method.honours_jerk() {
            checks.push(("jerk", peaks.jerk[i], lim.jerk));
        }
        for (quantity, value, limit) in checks {
            if value > tol(limit) {
                st.violations.push(Violation {
                    joint: i,
                    quantity,
                    value,
                    limit,
                });
            }
        }
    }
    c.stats = st;
    Ok(c)
}

/// Sign changes of the first difference of `x` (`rate`) or of `x` itself,
/// ignoring values within a dead band of 1e-9 of the largest magnitude (numerical
/// noise and flat stretches).
pub fn sign_changes(x: &[f64], rate: bool) -> usize {
    let vals: Vec<f64> = if rate {
        x.windows(2).map(|w| w[1] - w[0]).collect()
    } else {
        x.to_vec()
    };
    let scale = vals.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let band = 1e-9 * scale;
    let mut last = 0.0f64;
    let mut count = 0;
    for v in vals {
        if v.abs() <= band {
            continue;
        }
        if last != 0.0 && v.signum() != last {
            count += 1;
        }
        last = v.signum();
    }
    count
}

#[cfg(test)]
mod tests {
    use super::sign_changes;

    #[test]
    fn sign_changes_count_rate_reversals_and_ignore_flats() {
        assert_eq!(sign_changes(&[0.0, 1.0, 2.0, 2.0, 1.0, 0.0, 1.0], true), 2);
        assert_eq!(sign_changes(&[1.0, 1.0, 1.0], true), 0);
        assert_eq!(sign_changes(&[1.0, -1.0, 0.0, -2.0, 3.0], false), 2);
    }
}
