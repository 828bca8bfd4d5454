//! Continuity checks of recorded streams, with thresholds derived from the robot's limits
//! and the period (never from timing): the setpoint stream must not jump in q, q̇ or q̈,
//! the applied torque must not step.

use std::collections::HashMap;

use microrobot_messages::{
    JointSetpoint, JointState, TorqueCommand, setpoint_flags, state_flags, torque_flags,
};
use microrobot_model::Robot;

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
    /// The limits of the seed arm.
    pub fn seed_arm() -> Self {
        let robot = Robot::from_file(&super::seed_arm()).expect("seed arm");
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
