//! The stream invariants of the pipeline: what its three cyclic streams (setpoints,
//! torque commands, measured states) must satisfy, with thresholds derived from the
//! robot's limits and the period, never from timing. One set, in two forms: checks of
//! one pair of consecutive messages at a time, which the soak applies live as the
//! messages arrive, and checks of whole recorded streams, which the system tests apply
//! to what they recorded. Pure functions: no I/O.
//!
//! # Pairs of consecutive messages
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
//!
//! # Whole recorded streams
//!
//! The setpoint stream must not jump in q, q̇ or q̈, the applied torque must not step
//! (see [`setpoint_jumps`] and [`torque_steps`] for the bounds).

use std::collections::HashMap;

use microrobot_messages::{
    JointSetpoint, JointState, MAX_JOINTS, TorqueCommand, setpoint_flags, state_flags, torque_flags,
};
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

fn torque_slew_bound(b: &Bounds, i: usize, dt: f64) -> f64 {
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
        push(out, &at, "tau", i, d, torque_slew_bound(b, i, dt));
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
        push(out, &torque, "tau", i, d, torque_slew_bound(b, i, dt));
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
        push(out, &at, "tau", i, d, torque_slew_bound(b, i, b.period_s));
    }
}

/// Per-joint limits of the robot under test (SI).
#[derive(Debug, Clone)]
pub struct Limits {
    pub dof: usize,
    pub min: Vec<f64>,
    pub max: Vec<f64>,
    pub vel: Vec<f64>,
    pub acc: Vec<f64>,
    pub jerk: Vec<f64>,
    pub effort: Vec<f64>,
}

impl Limits {
    /// The limits of `robot`.
    pub fn of(robot: &Robot) -> Self {
        let j = robot.joints();
        let f = |g: fn(&microrobot_model::Joint) -> f64| j.iter().map(g).collect::<Vec<_>>();
        Self {
            dof: robot.dof(),
            min: f(|j| j.limits.min),
            max: f(|j| j.limits.max),
            vel: f(|j| j.limits.velocity),
            acc: f(|j| j.limits.acceleration),
            jerk: f(|j| j.limits.jerk),
            effort: f(|j| j.limits.effort),
        }
    }

    /// The largest torque change per step of `period_s` that a limit of "full effort in
    /// `full_scale_ms`" lets through (the dynamics' `torque_slew_ms`, the actuator's
    /// `torque_slope_ms`), per joint.
    pub fn torque_step_cap(&self, period_s: f64, full_scale_ms: f64) -> Vec<f64> {
        self.effort
            .iter()
            .map(|e| e * period_s / (full_scale_ms * 1e-3))
            .collect()
    }
}

/// Splits a stream into the runs of one publisher each: a new run starts wherever the
/// sequence number does not increase (a restarted process starts again at 1).
pub fn segments<T>(v: &[T], seq: impl Fn(&T) -> u64) -> Vec<&[T]> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..v.len() {
        if seq(&v[i]) <= seq(&v[i - 1]) {
            out.push(&v[start..i]);
            start = i;
        }
    }
    if start < v.len() {
        out.push(&v[start..]);
    }
    out
}

/// What [`setpoint_jumps`] found.
#[derive(Debug, Default)]
pub struct SetpointReport {
    /// Violations, as readable lines (empty: no jump).
    pub jumps: Vec<String>,
    /// Setpoints where the planner re-synchronised to the measured state (flag
    /// `HOLD_FOR_SAFE_STATE` rising): allowed, the actuator ignores setpoints then.
    pub resyncs: usize,
    /// Largest |q| excursion beyond the position limits (rad or m).
    pub beyond_position_limits: f64,
}

/// Checks every pair of consecutive setpoints of one planner process:
/// * planned motion: |q_b − q_a − ½(q̇_a + q̇_b)h| ≤ a_max h², |q̇_b − q̇_a| ≤ 1.01 a_max h,
///   |q̈_b − q̈_a| ≤ 1.01 j_max h (a jerk-limited stream; h = ticks × period);
/// * while following the measured state (`HOLD_FOR_SAFE_STATE`): the setpoint is a
///   recorded measured state (q clamped into the limits, exactly), or |Δq| ≤ 1.05 v_max h.
///   The mirror may move faster than v_max per planner tick: after a host stall the
///   catching-up planner ticks on with one state, then sees the arm's motion of the whole
///   stall in one tick;
/// * |q̇| ≤ 1.01 v_max and q within the position limits everywhere.
pub fn setpoint_jumps(
    sp: &[JointSetpoint],
    states: &[JointState],
    lim: &Limits,
    period_s: f64,
) -> SetpointReport {
    let mut r = SetpointReport::default();
    let hold = |s: &JointSetpoint| s.flags & setpoint_flags::HOLD_FOR_SAFE_STATE != 0;
    let mirrored: std::collections::HashSet<Vec<u64>> = states
        .iter()
        .map(|s| {
            (0..lim.dof)
                .map(|j| s.q[j].clamp(lim.min[j], lim.max[j]).to_bits())
                .collect()
        })
        .collect();
    let is_mirror = |s: &JointSetpoint| {
        let key: Vec<u64> = (0..lim.dof).map(|j| s.q[j].to_bits()).collect();
        mirrored.contains(&key)
    };
    for seg in segments(sp, |s| s.header.seq) {
        for w in seg.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            let ticks = b.header.tick.saturating_sub(a.header.tick).max(1);
            let h = ticks as f64 * period_s;
            if hold(b) && !hold(a) {
                r.resyncs += 1;
                continue;
            }
            for j in 0..lim.dof {
                let at = |what: &str, v: f64| {
                    format!(
                        "{what} {v:.3e} at joint {} tick {} (seq {} -> {})",
                        j + 1,
                        b.header.tick,
                        a.header.seq,
                        b.header.seq
                    )
                };
                if hold(b) {
                    let dq = (b.q[j] - a.q[j]).abs();
                    if dq > 1.05 * lim.vel[j] * h + 1e-9 && !is_mirror(b) {
                        r.jumps.push(at("measured-state follow jump (rad)", dq));
                    }
                    continue;
                }
                let dq = b.q[j] - a.q[j] - 0.5 * (a.qd[j] + b.qd[j]) * h;
                if dq.abs() > lim.acc[j] * h * h + 1e-9 {
                    r.jumps.push(at("position jump (rad)", dq));
                }
                let dqd = b.qd[j] - a.qd[j];
                if dqd.abs() > lim.acc[j] * h * 1.01 + 1e-9 {
                    r.jumps.push(at("velocity jump (rad/s)", dqd));
                }
                let dqdd = b.qdd[j] - a.qdd[j];
                if dqdd.abs() > lim.jerk[j] * h * 1.01 + 1e-9 {
                    r.jumps.push(at("acceleration jump (rad/s²)", dqdd));
                }
            }
        }
        for s in seg {
            for j in 0..lim.dof {
                if s.qd[j].abs() > lim.vel[j] * 1.01 + 1e-9 {
                    r.jumps.push(format!(
                        "velocity {} beyond the limit {} at joint {} tick {}",
                        s.qd[j],
                        lim.vel[j],
                        j + 1,
                        s.header.tick
                    ));
                }
                let beyond = (lim.min[j] - s.q[j]).max(s.q[j] - lim.max[j]).max(0.0);
                r.beyond_position_limits = r.beyond_position_limits.max(beyond);
            }
        }
    }
    r.jumps.truncate(20);
    r
}

/// Largest |Δτ_applied| per joint between consecutive states of one actuator process
/// (the first state of a process is skipped: it is published before any torque is
/// applied), over the states for which `keep` holds.
pub fn torque_slew(
    states: &[JointState],
    dof: usize,
    keep: impl Fn(&JointState) -> bool,
) -> Vec<f64> {
    let mut out = vec![0.0f64; dof];
    for seg in segments(states, |s| s.header.seq) {
        for w in seg.windows(2).skip(1) {
            if !keep(&w[0]) || !keep(&w[1]) {
                continue;
            }
            for (j, o) in out.iter_mut().enumerate() {
                *o = o.max((w[1].tau_applied[j] - w[0].tau_applied[j]).abs());
            }
        }
    }
    out
}

/// What [`torque_steps`] found.
#[derive(Debug, Default)]
pub struct TorqueStepReport {
    /// Steps (joint × state) beyond the healthy-motion bound.
    pub beyond_bound: usize,
    /// Of those, explained by a flag in the ramp window before them.
    pub after_flag: usize,
    /// Of those, explained only by a late command in the ramp window (a state that did
    /// not apply the next command: the arm ran open-loop under a held torque).
    pub after_late_command: usize,
    /// The rest: real steps, one line each.
    pub violations: Vec<String>,
}

/// The applied-torque steps (between consecutive states of one actuator process that
/// `keep` accepts) beyond the healthy-motion `bound[j]`. Torque never steps: such a
/// change must be at most `cap[j]` (the most the dynamics' slew limit and the actuator's
/// torque slope let through in one step) and lie within `ramp_steps` states after an
/// event that explains it, read from the streams, not from timing:
/// * a flag: a command cut to the slew limit (`SLEW_LIMITED`), a slope-limited step
///   (`SLOPE_LIMITED`), or a switch of the actuator's law (`COMMAND_STALE`,
///   `SAFE_STATE`; the blend back to the commands runs over `ramp_steps`);
/// * a late command: a state that did not apply the command after its predecessor's
///   (held or skipped `torque_seq`), or applied a command computed from another state
///   than the one after its predecessor's command's (`state_seq` held or skipped: the
///   dynamics was held up and saw the arm late, or saw several states at once). That is
///   a host stall as the streams see it: the free-running arm drifted open-loop under a
///   held torque, or feedback acted on an older state than usual, and then corrects a
///   real error, within the limits but faster than healthy motion.
pub fn torque_steps(
    states: &[JointState],
    torques: &[TorqueCommand],
    bound: &[f64],
    cap: &[f64],
    ramp_steps: usize,
    keep: impl Fn(&JointState) -> bool,
) -> TorqueStepReport {
    // The command a state applied: the newest one with its `torque_seq` stamped before it
    // (a restarted dynamics numbers from 1 again). Indexed once by seq, in stream order.
    let mut by_seq: HashMap<u64, Vec<&TorqueCommand>> = HashMap::new();
    for t in torques {
        by_seq.entry(t.header.seq).or_default().push(t);
    }
    let applied = |s: &JointState| {
        by_seq
            .get(&s.torque_seq)?
            .iter()
            .rev()
            .find(|t| t.header.stamp_ns <= s.header.stamp_ns)
            .copied()
    };
    let ramp_flags =
        state_flags::SLOPE_LIMITED | state_flags::COMMAND_STALE | state_flags::SAFE_STATE;
    let mut out = TorqueStepReport::default();
    for seg in segments(states, |s| s.header.seq) {
        // Index of the newest state so far with a flag, and with a late command.
        let (mut last_flag, mut last_late) = (None, None);
        for (i, b) in seg.iter().enumerate() {
            if b.flags & ramp_flags != 0
                || applied(b).is_some_and(|t| t.flags & torque_flags::SLEW_LIMITED != 0)
            {
                last_flag = Some(i);
            }
            if i > 0 && b.torque_seq != seg[i - 1].torque_seq.wrapping_add(1) {
                last_late = Some(i);
            }
            if i > 0
                && let (Some(t), Some(p)) = (applied(b), applied(&seg[i - 1]))
                && t.state_seq != p.state_seq.wrapping_add(1)
            {
                last_late = Some(i);
            }
            // The first state of a process is published before any torque is applied.
            if i < 2 || !keep(&seg[i - 1]) || !keep(b) {
                continue;
            }
            let a = &seg[i - 1];
            let recent = |last: Option<usize>| last.is_some_and(|k| i - k <= ramp_steps);
            let (after_flag, after_late) = (recent(last_flag), recent(last_late));
            for (j, (lo, hi)) in bound.iter().zip(cap).enumerate() {
                let d = (b.tau_applied[j] - a.tau_applied[j]).abs();
                if d <= *lo {
                    continue;
                }
                out.beyond_bound += 1;
                let within_cap = d <= hi * (1.0 + 1e-9);
                if within_cap && after_flag {
                    out.after_flag += 1;
                } else if within_cap && after_late {
                    out.after_late_command += 1;
                } else {
                    out.violations.push(format!(
                        "joint {}: applied torque {:.4} -> {:.4} N·m (step {d:.4} > healthy bound {lo:.4}, cap {hi:.4}) at state seq {} (lifecycle {}, flags {:#x}, torque_seq {} after {}; a flag in the last {ramp_steps} states: {after_flag}, a late command: {after_late}), command (seq, tau, flags, state_seq) {:?} after state_seq {:?}",
                        j + 1,
                        a.tau_applied[j],
                        b.tau_applied[j],
                        b.header.seq,
                        b.lifecycle,
                        b.flags,
                        b.torque_seq,
                        a.torque_seq,
                        applied(b).map(|t| (t.header.seq, t.tau[j], t.flags, t.state_seq)),
                        applied(a).map(|t| t.state_seq),
                    ));
                }
            }
        }
    }
    out
}

/// Largest |τ_applied| per joint.
pub fn torque_peak(states: &[JointState], dof: usize) -> Vec<f64> {
    let mut out = vec![0.0f64; dof];
    for s in states {
        for (j, o) in out.iter_mut().enumerate() {
            *o = o.max(s.tau_applied[j].abs());
        }
    }
    out
}

/// The torque step bound per joint: the slew of healthy motion (`healthy`), plus what a
/// switch between two laws blended over `ramp_steps` may add per step — at most the
/// distance between two torques of magnitude ≤ `peak`, divided by the ramp. An
/// unblended switch exceeds it by a factor of about `ramp_steps`.
pub fn torque_step_bound(healthy: &[f64], peak: &[f64], ramp_steps: f64) -> Vec<f64> {
    healthy
        .iter()
        .zip(peak)
        .map(|(h, p)| 1.5 * h + 2.0 * p / ramp_steps + 1e-3)
        .collect()
}

/// The newest state published at or before `stamp_ns`.
pub fn state_at(states: &[JointState], stamp_ns: u64) -> Option<&JointState> {
    states
        .iter()
        .take_while(|s| s.header.stamp_ns <= stamp_ns)
        .last()
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
