//! Continuity checks of the three cyclic streams, one pair of consecutive messages at a
//! time (pure functions: no I/O).
//!
//! Thresholds, per joint i, with dt the logical time between the two messages
//! (tick difference × period) and `tol` the relative tolerance (`--jump-tolerance`):
//! * setpoint: |Δq| ≤ vmax·dt·(1+tol) + ε_q and |Δq̇| ≤ amax·dt·(1+tol) + ε_q̇: the planner
//!   plans within the limits, so no honest stream moves faster. Setpoints flagged
//!   HOLD_FOR_SAFE_STATE mirror the measured arm (the actuator ignores torques then)
//!   and are not checked as the later message of a pair; the first setpoint after the
//!   hold is (it must start from the mirrored state).
//! * a restarted planner's first setpoints must start from the measured arm:
//!   |q − q_meas| ≤ vmax·(age+dt)·(1+tol) + ε_q,
//!   |q̇ − q̇_meas| ≤ max(amax, |q̈_meas|)·(age+dt)·(1+tol) + ε_q̇, with q̈_meas the arm's
//!   acceleration between the last two measured states (held by the actuator's own law
//!   it may decelerate faster than amax while the state ages).
//! * torque (commanded and applied): |Δτ| ≤ τmax·dt/T_SLEW·(1+tol): a full-scale change
//!   takes at least [`T_SLEW_S`]. The actuator blends every switch of its own over
//!   `ramp_ms` (20 ms by default) and the plan is jerk-limited, so an honest stream
//!   changes at least 2× slower than this bound. Commanded torque is judged only while
//!   the actuator follows it (not latched, not holding on its own) and not across a
//!   switch of dynamics between feedback and feed-forward (its measured state missing
//!   for `stale_ms`: a dead or stalled actuator); there the applied torque, always
//!   judged, is what reaches the arm.
//! * measured state: within one actuator process the plant integrates,
//!   |Δq − (q̇₀+q̇₁)/2·dt| ≤ ε_state (the trapezoid rule; its error amax·dt²/12 is far below
//!   ε_state); across an actuator restart the new process must resume exactly where the
//!   old one was: |Δq| ≤ ε_resume and |Δq̇| ≤ ε_resume (the simulated arm is frozen while
//!   its driver is down; a real arm would be held by its brakes). The shutdown state of
//!   a clean stop (backend inactive, brakes on: q̇ = 0, no torque) follows no plant step:
//!   only |Δq| ≤ ε_resume is checked there.

use microrobot_messages::{JointSetpoint, JointState, MAX_JOINTS, TorqueCommand, setpoint_flags};
use microrobot_model::Robot;
use serde::{Deserialize, Serialize};

/// Time for a full-scale (τmax) torque change that still counts as continuous.
pub const T_SLEW_S: f64 = 0.010;
/// Absolute slack on positions (rad or m): rounding of the planner's sampling.
pub const EPS_Q: f64 = 1e-9;
/// Absolute slack on velocities (rad/s or m/s).
pub const EPS_QD: f64 = 1e-9;
/// Slack on the integrated measured position within one actuator process.
pub const EPS_STATE: f64 = 1e-4;
/// Slack on the state a restarted actuator resumes from.
pub const EPS_RESUME: f64 = 1e-9;

/// The limits the checks use.
#[derive(Debug, Clone, Copy)]
pub struct Bounds {
    pub dof: usize,
    pub period_s: f64,
    pub tol: f64,
    pub vmax: [f64; MAX_JOINTS],
    pub amax: [f64; MAX_JOINTS],
    pub tau_max: [f64; MAX_JOINTS],
    /// Extra slack on measured values from sensor noise (6σ of the difference of two).
    pub noise_q: f64,
    pub noise_qd: f64,
}

impl Bounds {
    /// Bounds from `robot`'s limits at `rate_hz`, relative tolerance `tol`.
    pub fn new(robot: &Robot, rate_hz: f64, tol: f64, noise_q: f64, noise_qd: f64) -> Self {
        let mut b = Self {
            dof: robot.dof().min(MAX_JOINTS),
            period_s: 1.0 / rate_hz,
            tol,
            vmax: [0.0; MAX_JOINTS],
            amax: [0.0; MAX_JOINTS],
            tau_max: [0.0; MAX_JOINTS],
            noise_q: 6.0 * std::f64::consts::SQRT_2 * noise_q,
            noise_qd: 6.0 * std::f64::consts::SQRT_2 * noise_qd,
        };
        for (i, j) in robot.joints().iter().take(MAX_JOINTS).enumerate() {
            b.vmax[i] = j.limits.velocity;
            b.amax[i] = j.limits.acceleration;
            b.tau_max[i] = j.limits.effort;
        }
        b
    }

    fn dt_ticks(&self, from: u64, to: u64) -> f64 {
        to.saturating_sub(from).max(1) as f64 * self.period_s
    }
}

/// One discontinuity.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Jump {
    /// `CLOCK_MONOTONIC` ns of the later message.
    pub stamp_ns: u64,
    /// setpoint, torque, applied_torque, state.
    pub stream: String,
    /// q, qd, tau.
    pub field: String,
    pub joint: usize,
    /// |Δ| (or the deviation from the expected change).
    pub size: f64,
    pub bound: f64,
    /// What the pair was: within one process, across a restart, ...
    pub context: String,
}

/// Where a pair was checked: the later message's stamp, the stream, the kind of pair.
struct Site<'a>(u64, &'a str, &'a str);

fn push(out: &mut Vec<Jump>, at: &Site<'_>, field: &str, joint: usize, size: f64, bound: f64) {
    if size > bound || !size.is_finite() {
        out.push(Jump {
            stamp_ns: at.0,
            stream: at.1.into(),
            field: field.into(),
            joint,
            size,
            bound,
            context: at.2.into(),
        });
    }
}

/// Consecutive setpoints of one planner process.
pub fn setpoint_pair(b: &Bounds, prev: &JointSetpoint, next: &JointSetpoint, out: &mut Vec<Jump>) {
    if next.flags & setpoint_flags::HOLD_FOR_SAFE_STATE != 0 {
        return;
    }
    let dt = b.dt_ticks(prev.header.tick, next.header.tick);
    let k = 1.0 + b.tol;
    let at = Site(next.header.stamp_ns, "setpoint", "consecutive setpoints");
    for i in 0..b.dof {
        let dq = (next.q[i] - prev.q[i]).abs();
        let dqd = (next.qd[i] - prev.qd[i]).abs();
        push(out, &at, "q", i, dq, b.vmax[i] * dt * k + EPS_Q);
        push(out, &at, "qd", i, dqd, b.amax[i] * dt * k + EPS_QD);
    }
}

/// The first setpoint of a (re)started planner against the measured state `meas`,
/// which is `age_s` older than the setpoint, the arm accelerating at `meas_acc` (per
/// joint, measured between the last two states). Over `age_s` the arm's velocity
/// changes at its own acceleration, which while the actuator holds or damps on its own
/// is set by its hold law, not by the planner's limits: the velocity bound uses the
/// larger of the two.
pub fn setpoint_start(
    b: &Bounds,
    meas: &JointState,
    meas_acc: &[f64; MAX_JOINTS],
    age_s: f64,
    next: &JointSetpoint,
    out: &mut Vec<Jump>,
) {
    if next.flags & setpoint_flags::HOLD_FOR_SAFE_STATE != 0 {
        return;
    }
    let dt = age_s.max(0.0) + b.period_s;
    let k = 1.0 + b.tol;
    let at = Site(
        next.header.stamp_ns,
        "setpoint",
        "restarted planner vs measured state",
    );
    for i in 0..b.dof {
        let dq = (next.q[i] - meas.q[i]).abs();
        let dqd = (next.qd[i] - meas.qd[i]).abs();
        push(out, &at, "q", i, dq, b.vmax[i] * dt * k + EPS_Q + b.noise_q);
        push(
            out,
            &at,
            "qd",
            i,
            dqd,
            b.amax[i].max(meas_acc.get(i).map_or(0.0, |a| a.abs())) * dt * k + EPS_QD + b.noise_qd,
        );
    }
}

fn torque_slew(b: &Bounds, i: usize, dt: f64) -> f64 {
    b.tau_max[i] * dt / T_SLEW_S * (1.0 + b.tol)
}

/// Consecutive torque commands of one dynamics process.
pub fn torque_pair(b: &Bounds, prev: &TorqueCommand, next: &TorqueCommand, out: &mut Vec<Jump>) {
    let dt = b.dt_ticks(prev.header.tick, next.header.tick);
    let at = Site(
        next.header.stamp_ns,
        "torque",
        "consecutive torque commands",
    );
    for i in 0..b.dof {
        let d = (next.tau[i] - prev.tau[i]).abs();
        push(out, &at, "tau", i, d, torque_slew(b, i, dt));
    }
}

/// Consecutive measured states of one actuator process (`steps` plant steps apart):
/// the applied torque's slew, and the position integrating the velocity.
pub fn state_pair(
    b: &Bounds,
    prev: &JointState,
    next: &JointState,
    steps: u64,
    out: &mut Vec<Jump>,
) {
    let dt = steps.max(1) as f64 * b.period_s;
    let torque = Site(
        next.header.stamp_ns,
        "applied_torque",
        "consecutive plant steps",
    );
    let plant = Site(next.header.stamp_ns, "state", "plant step (q vs ∫q̇)");
    for i in 0..b.dof {
        let d = (next.tau_applied[i] - prev.tau_applied[i]).abs();
        push(out, &torque, "tau", i, d, torque_slew(b, i, dt));
        if steps == 1 {
            let expected = 0.5 * (prev.qd[i] + next.qd[i]) * dt;
            let dev = (next.q[i] - prev.q[i] - expected).abs();
            push(out, &plant, "q", i, dev, EPS_STATE + b.noise_q);
        }
    }
}

/// The actuator's shutdown state (its backend deactivated at a clean stop: drives
/// disabled, brakes on, so q̇ = 0 and no torque applied) against its last plant step. No
/// plant step lies between the two, so neither the integration nor the torque slew
/// applies; the arm must simply stay where it was: |Δq| ≤ ε_resume.
pub fn state_shutdown(b: &Bounds, prev: &JointState, next: &JointState, out: &mut Vec<Jump>) {
    let at = Site(
        next.header.stamp_ns,
        "state",
        "shutdown state (backend inactive) vs the last plant step",
    );
    for i in 0..b.dof {
        let dq = (next.q[i] - prev.q[i]).abs();
        push(out, &at, "q", i, dq, EPS_RESUME + b.noise_q);
    }
}

/// The first state of a restarted actuator against the last one of its predecessor.
pub fn state_resume(b: &Bounds, prev: &JointState, next: &JointState, out: &mut Vec<Jump>) {
    let at = Site(
        next.header.stamp_ns,
        "state",
        "restarted actuator vs its predecessor's last state",
    );
    for i in 0..b.dof {
        let dq = (next.q[i] - prev.q[i]).abs();
        let dqd = (next.qd[i] - prev.qd[i]).abs();
        push(out, &at, "q", i, dq, EPS_RESUME + b.noise_q);
        push(out, &at, "qd", i, dqd, EPS_RESUME + b.noise_qd);
    }
}

/// The applied torque of a restarted actuator's first plant step against the last one
/// its predecessor applied.
pub fn applied_torque_resume(
    b: &Bounds,
    prev: &JointState,
    next: &JointState,
    out: &mut Vec<Jump>,
) {
    let at = Site(
        next.header.stamp_ns,
        "applied_torque",
        "restarted actuator's first step vs its predecessor's last",
    );
    for i in 0..b.dof {
        let d = (next.tau_applied[i] - prev.tau_applied[i]).abs();
        push(out, &at, "tau", i, d, torque_slew(b, i, b.period_s));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds() -> Bounds {
        let mut b = Bounds {
            dof: 1,
            period_s: 1e-3,
            tol: 0.5,
            vmax: [0.0; MAX_JOINTS],
            amax: [0.0; MAX_JOINTS],
            tau_max: [0.0; MAX_JOINTS],
            noise_q: 0.0,
            noise_qd: 0.0,
        };
        b.vmax[0] = 2.0;
        b.amax[0] = 1.0;
        b.tau_max[0] = 50.0;
        b
    }

    fn sp(tick: u64, q: f64, qd: f64) -> JointSetpoint {
        let mut s = JointSetpoint::default();
        s.header.tick = tick;
        s.q[0] = q;
        s.qd[0] = qd;
        s.dof = 1;
        s
    }

    #[test]
    fn setpoint_steps_within_the_limits_pass_and_faster_ones_are_jumps() {
        let b = bounds();
        let mut out = Vec::new();
        // 2 rad/s for 1 ms = 2 mrad; 1.5 × that is the bound.
        setpoint_pair(&b, &sp(1, 0.0, 0.0), &sp(2, 0.0029, 0.0014), &mut out);
        assert!(out.is_empty(), "{out:?}");
        setpoint_pair(&b, &sp(1, 0.0, 0.0), &sp(2, 0.0031, 0.0), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].field, "q");
        // Two ticks apart allow twice the change.
        out.clear();
        setpoint_pair(&b, &sp(1, 0.0, 0.0), &sp(3, 0.0059, 0.0), &mut out);
        assert!(out.is_empty(), "{out:?}");
        // A hold setpoint (mirroring the measured arm) is not judged.
        let mut hold = sp(2, 1.0, 1.0);
        hold.flags = setpoint_flags::HOLD_FOR_SAFE_STATE;
        setpoint_pair(&b, &sp(1, 0.0, 0.0), &hold, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn the_applied_torque_slew_and_the_resume_state_are_checked() {
        let b = bounds();
        let mut a = JointState::default();
        let mut c = JointState::default();
        a.tau_applied[0] = 10.0;
        c.tau_applied[0] = 17.0; // bound 50 × 1 ms / 10 ms × 1.5 = 7.5
        let mut out = Vec::new();
        state_pair(&b, &a, &c, 1, &mut out);
        assert!(out.is_empty(), "{out:?}");
        c.tau_applied[0] = 18.0;
        state_pair(&b, &a, &c, 1, &mut out);
        assert_eq!(out.len(), 1);
        out.clear();
        // q must integrate qd within one process.
        c.tau_applied[0] = 10.0;
        a.qd[0] = 1.0;
        c.qd[0] = 1.0;
        c.q[0] = 1e-3;
        state_pair(&b, &a, &c, 1, &mut out);
        assert!(out.is_empty(), "{out:?}");
        c.q[0] = 2e-3;
        state_pair(&b, &a, &c, 1, &mut out);
        assert_eq!(out.len(), 1);
        out.clear();
        // A restart must resume exactly.
        state_resume(&b, &a, &a, &mut out);
        assert!(out.is_empty());
        state_resume(&b, &a, &c, &mut out);
        assert_eq!(out.len(), 1, "{out:?}");
        out.clear();
        // The shutdown state: the brakes stop the arm where it is (q̇ = 0, no torque).
        let mut braked = a;
        braked.qd[0] = 0.0;
        braked.tau_applied[0] = 0.0;
        state_shutdown(&b, &a, &braked, &mut out);
        assert!(out.is_empty(), "{out:?}");
        braked.q[0] += 1e-3;
        state_shutdown(&b, &a, &braked, &mut out);
        assert_eq!(out.len(), 1, "{out:?}");
    }
}
