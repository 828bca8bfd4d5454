//! Minimum final time per method (the seed's "optimal planning"), found by search:
//! the shortest tf whose trajectory respects the limits the method can honour
//! (velocity and acceleration for cubic and LSPB; plus jerk for quintic and soft
//! motion), the position range, and the torque limits.
//!
//! Check at a given tf: kinematic peaks are the library's exact extremes of the
//! piecewise polynomials; torques are evaluated by RNEA at `check_samples + 1`
//! uniformly spaced times on [0, duration]. Search: start at the library's
//! kinematic minimum ([`microrobot_trajectory::minimum_duration`]); if that fails
//! the check, grow tf by ×1.5 until it passes (up to [`MAX_TF`]) and bisect the
//! last failing / first passing bracket to 1e-6 relative. Feasibility is assumed
//! monotonic in tf above the kinematic minimum (true for the velocity,
//! acceleration and jerk bounds; for torques it holds unless gravity dominates
//! differently along different paths).

use anyhow::Result;
use microrobot_model::{ModelData, Robot, rnea};
use microrobot_trajectory::minimum_duration;

use super::cases::{LIMIT_TOL, Method, plan, request};
use super::motion::StudyMotion;

/// Largest final time the search tries (s).
pub const MAX_TF: f64 = 1.0e4;

/// Result of the search for one method.
#[derive(Debug, Clone)]
pub struct MinTime {
    /// Method.
    pub method: Method,
    /// The library's kinematic minimum (s), if it could compute one.
    pub kinematic: Option<f64>,
    /// The searched minimum (s), `None` when no tf up to [`MAX_TF`] passes.
    pub minimum: Option<f64>,
    /// What binds just below the minimum (e.g. "acceleration j1").
    pub binding: String,
    /// Check evaluations made.
    pub evaluations: usize,
}

/// The first limit a trajectory at `tf` breaks, or `None` when it respects all.
pub fn check(
    robot: &Robot,
    motion: &StudyMotion,
    method: Method,
    tf: f64,
    check_samples: usize,
) -> Option<String> {
    let traj = match plan(robot, motion, method, tf) {
        Ok(t) => t,
        Err(e) => return Some(format!("not plannable ({e})")),
    };
    let p = traj.peaks();
    for (i, j) in robot.joints().iter().enumerate() {
        let l = &j.limits;
        let tol = LIMIT_TOL * (l.max - l.min).abs().max(1.0);
        if p.position_min[i] < l.min - tol || p.position_max[i] > l.max + tol {
            return Some(format!("position j{}", i + 1));
        }
        let mut checks = vec![
            ("velocity", p.velocity[i], l.velocity),
            ("acceleration", p.acceleration[i], l.acceleration),
        ];
        if method.honours_jerk() {
            checks.push(("jerk", p.jerk[i], l.jerk));
        }
        for (what, v, lim) in checks {
            if v > lim * (1.0 + LIMIT_TOL) {
                return Some(format!("{what} j{}", i + 1));
            }
        }
    }
    let mut data = ModelData::new(robot);
    let n = check_samples.max(2);
    let d = traj.duration();
    for k in 0..=n {
        let s = traj.sample(d * k as f64 / n as f64);
        let tau = rnea(robot, &mut data, &s.q, &s.qd, &s.qdd);
        for (i, j) in robot.joints().iter().enumerate() {
            if tau[i].abs() > j.limits.effort * (1.0 + LIMIT_TOL) {
                return Some(format!(
                    "{} j{}",
                    super::units::Units(j.kind).effort_word(),
                    i + 1
                ));
            }
        }
    }
    None
}

/// Searches the minimum final time of `method`.
pub fn search(
    robot: &Robot,
    motion: &StudyMotion,
    method: Method,
    check_samples: usize,
) -> Result<MinTime> {
    let kinematic = minimum_duration(&request(robot, motion, method, 1.0)).ok();
    let mut evaluations = 0;
    let mut fails = |tf: f64| {
        evaluations += 1;
        check(robot, motion, method, tf, check_samples)
    };
    let mut lo = kinematic.unwrap_or(1e-3);
    let first = fails(lo);
    let Some(mut why) = first else {
        return Ok(MinTime {
            method,
            kinematic,
            minimum: Some(lo),
            binding: "kinematic limits (library minimum)".into(),
            evaluations,
        });
    };
    let mut hi = lo * 1.5;
    loop {
        match fails(hi) {
            None => break,
            Some(w) => {
                why = w;
                lo = hi;
                hi *= 1.5;
                if hi > MAX_TF {
                    return Ok(MinTime {
                        method,
                        kinematic,
                        minimum: None,
                        binding: format!("{why} (still at {lo:.1} s)"),
                        evaluations,
                    });
                }
            }
        }
    }
    while hi - lo > 1e-6 * hi {
        let m = 0.5 * (lo + hi);
        match fails(m) {
            None => hi = m,
            Some(w) => {
                why = w;
                lo = m;
            }
        }
    }
    Ok(MinTime {
        method,
        kinematic,
        minimum: Some(hi),
        binding: why,
        evaluations,
    })
}
