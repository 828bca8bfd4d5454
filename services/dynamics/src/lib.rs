//! The dynamics service: woken by each joint setpoint, it computes the joint torques
//! and publishes a torque command.
//!
//! * Feedback on (default), computed torque on the measured state (q, q̇):
//!   `τ = M(q)(q̈d + Kp(qd − q̂) + Kd(q̇d − q̂̇)) + h(q, q̇)` with Kp in 1/s², Kd in 1/s,
//!   where (q̂, q̂̇) is the measured state predicted one period ahead under q̈d
//!   (`delay_compensation`, default on; off: q̂ = q). The measured state is the result
//!   of the previous torque, one period older than the setpoint; without the
//!   prediction the loop tracks about q̇·period behind. It is evaluated in one
//!   Newton-Euler pass, `τ = rnea(q, q̇, a)` with `a` the bracket, which equals
//!   `M(q)a + h(q, q̇)` without forming M (Featherstone, RBDA §5.3).
//! * Feedback off, or measured state stale: feed-forward Newton-Euler
//!   `τ = rnea(qd, q̇d, q̈d)`, flagged `STATE_STALE` when feedback was wanted.
//! * Every τ is clamped to the joint's effort limit and flagged `CLAMPED`.
//! * Then slew-limited (`torque_slew_ms`, default 20 ms for a full-scale change):
//!   `|τᵢ − τᵢ,prev| ≤ τmaxᵢ · Δt / torque_slew_ms`, Δt the logical time (ticks × period)
//!   since the previous command, flagged `SLEW_LIMITED`. A jerk-limited plan never needs
//!   more; what does is feedback reacting to a state that jumped — after a host stall the
//!   free-running arm has moved open-loop for tens of ms — and a switch between feedback
//!   and feed-forward. Those now reach the arm as ramps, not steps.
//!
//! In lockstep, setpoint k uses exactly measured state k−1 (the state the actuator
//! published after applying torque k−1); otherwise the newest state younger than
//! `stale_ms`. Inputs are validated (finite, dof, increasing seq, fresh, within the
//! joint limits) and refused ones are counted; no torque is published for them.
//! The computation lives in [`DynamicsCore`] (no IPC); the service's stage (its ports
//! and wake-up) in `stage.rs`.

pub mod config;
mod stage;

pub use config::DynamicsConfig;
pub use stage::run;

use microrobot_messages::{
    Header, JointSetpoint, JointState, MAX_JOINTS, TorqueCommand, state_flags, torque_flags,
};
use microrobot_model::{JointVector, ModelData, Robot, rnea};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::validate::{
    JointBounds, Refusal, SeqTracker, check_fresh, check_setpoint, check_state,
};

/// Cumulative counters of the dynamics service.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counters {
    /// Torque commands computed.
    pub cycles: u64,
    /// Setpoints and states refused.
    pub refused: u64,
    /// Torques computed without (wanted) feedback because the state was stale or missing.
    pub stale_cycles: u64,
    /// Torques clamped to an effort limit.
    pub clamped_cycles: u64,
    /// Torques slew-limited (see `torque_slew_ms`).
    pub slew_limited_cycles: u64,
}

/// The torque computation, independent of IPC and clocks.
pub struct DynamicsCore {
    robot: Robot,
    data: ModelData,
    dof: usize,
    feedback: bool,
    predict: bool,
    period_s: f64,
    kp: f64,
    kd: f64,
    lockstep: bool,
    stale_ns: u64,
    effort: [f64; MAX_JOINTS],
    /// Largest |Δτᵢ| per tick (N·m or N); +∞: no slew limit.
    slew_per_tick: [f64; MAX_JOINTS],
    /// The previous command's torque and tick (the slew limit's reference).
    last_torque: Option<([f64; MAX_JOINTS], u64)>,
    bounds: JointBounds,
    sp_seq: SeqTracker,
    st_seq: SeqTracker,
    state: Option<JointState>,
    torque_seq: u64,
    last_tick_value: Option<u64>,
    /// Counters for the status.
    pub counters: Counters,
    /// Largest |τ| commanded per joint (after clamping).
    pub peak_torque: [f64; MAX_JOINTS],
    /// Why the last refused setpoint or state was refused.
    pub last_refusal: Option<Refusal>,
}

impl DynamicsCore {
    /// A core for `robot` with the settings of `dynamics` and the rate and watchdog
    /// settings of `cfg`.
    pub fn new(robot: &Robot, cfg: &PipelineConfig, dynamics: &DynamicsConfig) -> Self {
        let mut effort = [0.0; MAX_JOINTS];
        let mut bounds = JointBounds {
            q_min: [0.0; MAX_JOINTS],
            q_max: [0.0; MAX_JOINTS],
            qd_max: [0.0; MAX_JOINTS],
        };
        for (i, j) in robot.joints().iter().enumerate() {
            effort[i] = j.limits.effort;
            bounds.q_min[i] = j.limits.min;
            bounds.q_max[i] = j.limits.max;
            bounds.qd_max[i] = j.limits.velocity;
        }
        let mut slew_per_tick = [f64::INFINITY; MAX_JOINTS];
        if dynamics.torque_slew_ms > 0.0 {
            let ticks_per_slew = dynamics.torque_slew_ms * 1e-3 * cfg.rate_hz;
            for i in 0..robot.dof() {
                slew_per_tick[i] = effort[i] / ticks_per_slew;
            }
        }
        Self {
            data: ModelData::new(robot),
            dof: robot.dof(),
            robot: robot.clone(),
            feedback: dynamics.feedback,
            predict: dynamics.delay_compensation,
            period_s: 1.0 / cfg.rate_hz,
            kp: dynamics.kp_per_s2,
            kd: dynamics.kd_per_s,
            lockstep: cfg.lockstep,
            stale_ns: cfg.watchdog.stale_ns(),
            effort,
            slew_per_tick,
            last_torque: None,
            bounds,
            sp_seq: SeqTracker::new(cfg.watchdog.stale_ns()),
            st_seq: SeqTracker::new(cfg.watchdog.stale_ns()),
            state: None,
            torque_seq: 0,
            last_tick_value: None,
            counters: Counters::default(),
            peak_torque: [0.0; MAX_JOINTS],
            last_refusal: None,
        }
    }

    /// Sequence gaps seen on the setpoint stream (and, in lockstep, on the state stream;
    /// free-running, only the newest state matters and older ones may be overwritten).
    pub fn lost_messages(&self) -> u64 {
        self.sp_seq.lost + if self.lockstep { self.st_seq.lost } else { 0 }
    }

    /// Logical time of the last setpoint (its tick).
    pub fn last_tick(&self) -> Option<u64> {
        self.last_tick_value
    }

    /// Logical time (tick) of the newest accepted measured state.
    pub fn state_tick(&self) -> Option<u64> {
        self.state.map(|s| s.header.tick)
    }

    /// Validates a measured state (from `publisher`, received at `now_ns`) and keeps it
    /// as the newest.
    pub fn accept_state(
        &mut self,
        msg: &JointState,
        publisher: u128,
        now_ns: u64,
    ) -> Result<(), Refusal> {
        self.accept_state_from(msg, publisher, now_ns, || true)
    }

    /// [`Self::accept_state`], where a state that would take the stream over (its owner
    /// silent for `stale_ms`) is taken only if `from_pipeline()` says the pipeline's supervisor started its
    /// process ([`microrobot_runtime::provenance`]); another's is refused as an outsider's.
    pub fn accept_state_from(
        &mut self,
        msg: &JointState,
        publisher: u128,
        now_ns: u64,
        from_pipeline: impl FnOnce() -> bool,
    ) -> Result<(), Refusal> {
        let r = check_state(msg, self.dof).and_then(|()| {
            self.st_seq
                .accept_from(publisher, msg.header.seq, now_ns, from_pipeline)
        });
        match r {
            Ok(()) => {
                // The actuator's final state repeats its last period's tick: in lockstep
                // the setpoint of the next tick was computed from the state before it
                // (whether or not the final one arrived first), so it is not kept.
                if !(self.lockstep && msg.flags & state_flags::FINAL != 0) {
                    self.state = Some(*msg);
                }
                Ok(())
            }
            Err(e) => {
                self.counters.refused += 1;
                self.last_refusal = Some(e);
                Err(e)
            }
        }
    }

    /// The state to use for setpoint `sp` at `now_ns`, if fresh enough.
    fn usable_state(&self, sp: &JointSetpoint, now_ns: u64) -> Option<JointState> {
        let s = self.state?;
        if self.lockstep {
            (s.header.tick + 1 == sp.header.tick).then_some(s)
        } else {
            check_fresh(s.header.stamp_ns, now_ns, self.stale_ns)
                .ok()
                .map(|()| s)
        }
    }

    /// Validates setpoint `sp` (from `publisher`) and computes its torque command
    /// (stamped `now_ns`). A refused setpoint gives no command.
    pub fn compute(
        &mut self,
        sp: &JointSetpoint,
        publisher: u128,
        now_ns: u64,
    ) -> Result<TorqueCommand, Refusal> {
        self.compute_from(sp, publisher, now_ns, || true)
    }

    /// [`Self::compute`], where a setpoint that would take the stream over (its owner
    /// silent for `stale_ms`) is taken only if `from_pipeline()` says the pipeline's supervisor started its
    /// process; another's is refused as an outsider's and gives no torque.
    pub fn compute_from(
        &mut self,
        sp: &JointSetpoint,
        publisher: u128,
        now_ns: u64,
        from_pipeline: impl FnOnce() -> bool,
    ) -> Result<TorqueCommand, Refusal> {
        let r = check_setpoint(sp, self.dof, &self.bounds)
            .and_then(|()| {
                if self.lockstep {
                    Ok(())
                } else {
                    check_fresh(sp.header.stamp_ns, now_ns, self.stale_ns)
                }
            })
            .and_then(|()| {
                self.sp_seq
                    .accept_from(publisher, sp.header.seq, now_ns, from_pipeline)
            });
        if let Err(e) = r {
            self.counters.refused += 1;
            self.last_refusal = Some(e);
            return Err(e);
        }
        self.last_tick_value = Some(sp.header.tick);
        let n = self.dof;
        let qd_ = JointVector::from_column_slice(&sp.q);
        let vd = JointVector::from_column_slice(&sp.qd);
        let ad = JointVector::from_column_slice(&sp.qdd);
        let mut flags = 0;
        let state = if self.feedback {
            self.usable_state(sp, now_ns)
        } else {
            None
        };
        let mut tau = match state {
            Some(s) => {
                flags |= torque_flags::FEEDBACK;
                let q = JointVector::from_column_slice(&s.q);
                let v = JointVector::from_column_slice(&s.qd);
                let mut a = JointVector::zeros();
                // The state is one period older than the setpoint (it is the result of the
                // previous torque); with delay compensation it is first predicted to the
                // setpoint's time under the desired acceleration.
                // Free-running, the state may be more than one tick old (after a missed
                // tick the planner catches up), or as new as the setpoint or newer (the
                // actuator kept stepping while the planner was held up, e.g. by a host
                // stall, and the planner now catches up): predict over the actual, signed,
                // tick distance, so the error is taken at the setpoint's time (a state 20
                // ticks ahead predicted one tick further gave a 20-tick "error" and a
                // torque step; found by `microrobot soak`).
                let ticks = (sp.header.tick as i64 - s.header.tick as i64).clamp(-10, 10);
                let h = if self.predict {
                    self.period_s * ticks as f64
                } else {
                    0.0
                };
                for i in 0..n {
                    let qp = q[i] + v[i] * h + 0.5 * ad[i] * h * h;
                    let vp = v[i] + ad[i] * h;
                    a[i] = ad[i] + self.kp * (qd_[i] - qp) + self.kd * (vd[i] - vp);
                }
                rnea(&self.robot, &mut self.data, &q, &v, &a)
            }
            None => {
                if self.feedback {
                    flags |= torque_flags::STATE_STALE;
                    self.counters.stale_cycles += 1;
                }
                rnea(&self.robot, &mut self.data, &qd_, &vd, &ad)
            }
        };
        let mut clamped = false;
        for i in 0..n {
            let lim = self.effort[i];
            if tau[i] > lim {
                tau[i] = lim;
                clamped = true;
            } else if tau[i] < -lim {
                tau[i] = -lim;
                clamped = true;
            } else if !tau[i].is_finite() {
                // A singular model at this state: refuse rather than forward garbage.
                self.counters.refused += 1;
                self.last_refusal = Some(Refusal::NonFinite);
                return Err(Refusal::NonFinite);
            }
        }
        if clamped {
            flags |= torque_flags::CLAMPED;
            self.counters.clamped_cycles += 1;
        }
        if let Some((prev, prev_tick)) = self.last_torque {
            // A tick that does not advance (a restarted planner counts from its own start)
            // still allows one tick's change: the bound never freezes the torque.
            let dt_ticks = sp.header.tick.saturating_sub(prev_tick).max(1) as f64;
            let mut limited = false;
            for i in 0..n {
                let max = self.slew_per_tick[i] * dt_ticks;
                let d = tau[i] - prev[i];
                if d > max {
                    tau[i] = prev[i] + max;
                    limited = true;
                } else if d < -max {
                    tau[i] = prev[i] - max;
                    limited = true;
                }
            }
            if limited {
                flags |= torque_flags::SLEW_LIMITED;
                self.counters.slew_limited_cycles += 1;
            }
        }
        let mut kept = [0.0; MAX_JOINTS];
        kept[..n].copy_from_slice(&tau.as_slice()[..n]);
        self.last_torque = Some((kept, sp.header.tick));
        self.torque_seq += 1;
        self.counters.cycles += 1;
        let mut out = TorqueCommand {
            header: Header {
                seq: self.torque_seq,
                tick: sp.header.tick,
                stamp_ns: now_ns,
                source_stamp_ns: sp.header.source_stamp_ns,
            },
            setpoint_seq: sp.header.seq,
            state_seq: state.map(|s| s.header.seq).unwrap_or(u64::MAX),
            dof: n as u32,
            flags,
            ..Default::default()
        };
        for i in 0..n {
            out.tau[i] = tau[i];
            out.q_desired[i] = sp.q[i];
            self.peak_torque[i] = self.peak_torque[i].max(tau[i].abs());
        }
        Ok(out)
    }
}
