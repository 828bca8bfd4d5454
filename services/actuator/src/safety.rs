//! The actuator's own safety layer, independent of the rest of the pipeline: what
//! torque to apply given the age of the torque commands.
//!
//! * Commands fresh → apply them.
//! * No command for `stale_ms` → **hold**: the actuator's own computed-torque PD holds
//!   the position measured when the commands went stale; it follows commands again as
//!   soon as they are fresh.
//! * No command for `fault_ms` → **safe state latched**: hold (or damp to rest, then
//!   hold), ignoring commands until a Reset (or, with `auto_resume`, fresh commands).
//!
//! Every switch between command torque and the actuator's own law is blended linearly
//! over `ramp_ms` (counted in plant steps, so lockstep runs stay deterministic): never a
//! torque step. Last of all a torque slope (`torque_slope_ms`, a drive's CiA 402
//! object 0x6087) bounds every step's change, `|Δτᵢ| ≤ τmaxᵢ·T/torque_slope_ms`, whatever
//! the commands do — except the first torque after the drive is switched on, which takes
//! over from the brakes. The hold and damp laws use the nominal model:
//! `τ = M(q)(Kp (q_hold − q) − Kd qd) + h(q, qd)` (damp: Kp = 0 until every |qd| < 1 mrad/s).

use microrobot_model::{JointVector, ModelData, Robot, mass_matrix, nonlinear_effects};
use microrobot_runtime::config::SafeStateMode;

/// Who decides the applied torque.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// The torque commands.
    Command,
    /// Stale commands: the actuator holds, not latched.
    StaleHold,
    /// Safe state latched: hold or damp until reset.
    Safe,
}

/// The safety layer's state.
#[derive(Debug, Clone)]
pub struct Safety {
    model: Robot,
    data: ModelData,
    dof: usize,
    kp: f64,
    kd: f64,
    safe_mode: SafeStateMode,
    ramp_steps: u32,
    mode: Mode,
    damping: bool,
    q_hold: JointVector,
    blend_from: JointVector,
    blend_step: u32,
    last_applied: JointVector,
    /// Largest |Δτᵢ| per plant step (+∞: no slope limit).
    slope_per_step: JointVector,
    /// Whether `last_applied` was applied (the slope's reference); false until the first
    /// torque after switch-on.
    slope_armed: bool,
    slope_limited: bool,
}

/// Velocity below which damping is considered at rest (rad/s).
const REST_QD: f64 = 1e-3;

impl Safety {
    /// A layer using `model` (the nominal robot), gains in 1/s² and 1/s, the ramp in
    /// steps.
    pub fn new(model: &Robot, kp: f64, kd: f64, safe_mode: SafeStateMode, ramp_steps: u32) -> Self {
        Self {
            data: ModelData::new(model),
            dof: model.dof(),
            model: model.clone(),
            kp,
            kd,
            safe_mode,
            ramp_steps,
            mode: Mode::Command,
            damping: false,
            q_hold: JointVector::zeros(),
            blend_from: JointVector::zeros(),
            blend_step: u32::MAX,
            last_applied: JointVector::zeros(),
            slope_per_step: JointVector::repeat(f64::INFINITY),
            slope_armed: false,
            slope_limited: false,
        }
    }

    /// Limits each step's torque change on joint i to `per_step[i]` (N·m or N).
    pub fn with_slope(mut self, per_step: &JointVector) -> Self {
        self.slope_per_step = *per_step;
        self
    }

    /// The drive was (re-)enabled: its first torque takes over from the brakes, not from a
    /// torque applied before.
    pub fn on_switch_on(&mut self) {
        self.slope_armed = false;
    }

    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Whether the safe state is latched.
    pub fn latched(&self) -> bool {
        self.mode == Mode::Safe
    }

    fn switch(&mut self, mode: Mode, q: &JointVector) {
        if mode == self.mode {
            return;
        }
        if mode != Mode::Command && self.mode == Mode::Command {
            self.q_hold = *q;
        }
        if mode == Mode::Safe {
            self.damping = self.safe_mode == SafeStateMode::Damp;
        }
        self.mode = mode;
        self.blend_from = self.last_applied;
        self.blend_step = 0;
    }

    /// Commands went stale (not latched): hold from measured `q`.
    pub fn on_stale(&mut self, q: &JointVector) {
        if self.mode == Mode::Command {
            self.switch(Mode::StaleHold, q);
        }
    }

    /// Commands missing for `fault_ms`: latch the safe state.
    pub fn on_fault(&mut self, q: &JointVector) {
        if self.mode != Mode::Safe {
            let from_command = self.mode == Mode::Command;
            self.switch(Mode::Safe, q);
            if !from_command {
                // Keep holding where the stale hold started.
            }
        }
    }

    /// Commands fresh again: follow them unless latched.
    pub fn on_fresh(&mut self, q: &JointVector) {
        if self.mode == Mode::StaleHold {
            self.switch(Mode::Command, q);
        }
    }

    /// Leaves the safe state (Reset, or auto-resume): follow commands, blended.
    pub fn reset(&mut self, q: &JointVector) {
        if self.mode != Mode::Command {
            self.switch(Mode::Command, q);
        }
    }

    /// The torque to apply this step, given the command torque (if any) and the measured
    /// state. Blends after every mode switch.
    pub fn torque(
        &mut self,
        command: Option<&JointVector>,
        q: &JointVector,
        qd: &JointVector,
    ) -> JointVector {
        let target = match (self.mode, command) {
            (Mode::Command, Some(c)) => *c,
            _ => self.own_law(q, qd),
        };
        let mut out = if self.blend_step < self.ramp_steps {
            self.blend_step += 1;
            let a = self.blend_step as f64 / self.ramp_steps as f64;
            self.blend_from * (1.0 - a) + target * a
        } else {
            target
        };
        self.slope_limited = false;
        if self.slope_armed {
            for i in 0..self.dof {
                let max = self.slope_per_step[i];
                let d = out[i] - self.last_applied[i];
                if d > max {
                    out[i] = self.last_applied[i] + max;
                    self.slope_limited = true;
                } else if d < -max {
                    out[i] = self.last_applied[i] - max;
                    self.slope_limited = true;
                }
            }
        }
        self.slope_armed = true;
        self.last_applied = out;
        out
    }

    /// Whether the last [`Safety::torque`] was cut by the torque slope.
    pub fn slope_limited(&self) -> bool {
        self.slope_limited
    }

    /// Starts a blend from `tau` (a restarted actuator continues from the torque its
    /// predecessor applied last instead of from zero).
    pub fn blend_from(&mut self, tau: &JointVector) {
        self.last_applied = *tau;
        self.blend_from = *tau;
        self.blend_step = 0;
        self.slope_armed = true;
    }

    /// Records the torque actually applied (when the caller bypasses [`Safety::torque`]).
    pub fn set_last_applied(&mut self, tau: &JointVector) {
        self.last_applied = *tau;
        self.slope_armed = true;
    }

    fn own_law(&mut self, q: &JointVector, qd: &JointVector) -> JointVector {
        if self.damping && (0..self.dof).all(|i| qd[i].abs() < REST_QD) {
            self.damping = false;
            self.q_hold = *q;
        }
        let kp = if self.damping { 0.0 } else { self.kp };
        let mut a = JointVector::zeros();
        for i in 0..self.dof {
            a[i] = kp * (self.q_hold[i] - q[i]) - self.kd * qd[i];
        }
        let m = mass_matrix(&self.model, &mut self.data, q);
        let h = nonlinear_effects(&self.model, &mut self.data, q, qd);
        let mut tau = m * a + h;
        for i in self.dof..tau.len() {
            tau[i] = 0.0;
        }
        tau
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot() -> Robot {
        let text = r#"
[robot]
name = "pendulum"
gravity_mps2 = [0.0, -9.81, 0.0]
[[joints]]
name = "j1"
kind = "revolute"
dh = { theta_deg = 0.0, d_mm = 0.0, a_mm = 500.0, alpha_deg = 0.0 }
limits = { min_deg = -180.0, max_deg = 180.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 20.0 }
link = { mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }
"#;
        Robot::from_toml_str(text, "p.toml").unwrap()
    }

    #[test]
    fn commands_pass_through_until_stale_then_hold_blends_without_a_step() {
        let r = robot();
        let mut s = Safety::new(&r, 100.0, 20.0, SafeStateMode::Hold, 10);
        let q = JointVector::zeros();
        let qd = JointVector::zeros();
        let mut cmd = JointVector::zeros();
        cmd[0] = 1.0;
        assert_eq!(s.torque(Some(&cmd), &q, &qd)[0], 1.0);
        s.on_stale(&q);
        assert_eq!(s.mode(), Mode::StaleHold);
        // gravity torque at q = 0 is 4.905 N·m; the blend moves there in 10 equal steps.
        let mut prev = 1.0;
        for k in 1..=10 {
            let t = s.torque(Some(&cmd), &q, &qd)[0];
            assert!(
                (t - prev).abs() <= (4.905 - 1.0) / 10.0 + 1e-9,
                "step {k}: {prev} -> {t}"
            );
            prev = t;
        }
        assert!((prev - 4.905).abs() < 1e-9);
        s.on_fresh(&q);
        assert_eq!(s.mode(), Mode::Command);
    }

    #[test]
    fn safe_state_latches_until_reset() {
        let r = robot();
        let mut s = Safety::new(&r, 100.0, 20.0, SafeStateMode::Hold, 0);
        let q = JointVector::zeros();
        s.on_stale(&q);
        s.on_fault(&q);
        assert!(s.latched());
        s.on_fresh(&q);
        assert!(s.latched(), "fresh commands alone do not unlatch");
        s.reset(&q);
        assert_eq!(s.mode(), Mode::Command);
    }

    #[test]
    fn damp_mode_brakes_velocity_then_holds() {
        let r = robot();
        let mut s = Safety::new(&r, 100.0, 20.0, SafeStateMode::Damp, 0);
        let q = JointVector::zeros();
        let mut qd = JointVector::zeros();
        qd[0] = 1.0;
        s.on_fault(&q);
        let t = s.torque(None, &q, &qd)[0];
        // M = 0.25, a = −20 → −5 N·m, plus gravity 4.905.
        assert!((t - (4.905 - 5.0)).abs() < 1e-9, "{t}");
    }

    #[test]
    fn the_torque_slope_bounds_every_step_except_the_switch_on() {
        let r = robot();
        let mut s = Safety::new(&r, 100.0, 20.0, SafeStateMode::Hold, 0)
            .with_slope(&JointVector::repeat(2.0));
        let q = JointVector::zeros();
        let mut cmd = JointVector::zeros();
        cmd[0] = 10.0;
        // Switch-on: the drive takes over from the brakes at the commanded torque.
        assert_eq!(s.torque(Some(&cmd), &q, &q)[0], 10.0);
        assert!(!s.slope_limited());
        cmd[0] = -5.0;
        let mut prev = 10.0;
        for k in 0..7 {
            let t = s.torque(Some(&cmd), &q, &q)[0];
            assert!((t - prev).abs() <= 2.0 + 1e-12, "step {k}: {prev} -> {t}");
            assert!(s.slope_limited(), "step {k} is cut");
            prev = t;
        }
        assert_eq!(prev, -4.0);
        assert_eq!(s.torque(Some(&cmd), &q, &q)[0], -5.0);
        assert!(!s.slope_limited());
        s.on_switch_on();
        cmd[0] = 20.0;
        assert_eq!(s.torque(Some(&cmd), &q, &q)[0], 20.0);
    }
}
