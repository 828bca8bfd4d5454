//! The whole lockstep loop of one pipeline in one thread, no IPC: the planner, dynamics
//! and actuator cores (the same code the three processes run) wired in the order the
//! processes run them in lockstep, with a logical clock. `microrobot replay
//! --closed-loop` holds a recorded lockstep run against it, message by message, bit for
//! bit: the proof that the processes add nothing but transport to the sampled loop.
//!
//! Order per tick k (as in the services' lockstep loops): the actuator's state k reaches
//! dynamics and planner; the planner checks it and ticks (setpoint k); dynamics computes
//! torque k from setpoint k and state k; the actuator checks its watchdog and takes one
//! plant step of one period with torque k (zero-order hold), giving state k+1. Before
//! the first tick the actuator publishes its initial state.

use anyhow::{Context as _, Result, anyhow, bail};
use microrobot_actuator::{ActuatorConfig, ActuatorCore, SimArm, initial_q};
use microrobot_dynamics::{DynamicsConfig, DynamicsCore};
use microrobot_messages::{JointSetpoint, JointState, TorqueCommand};
use microrobot_planner::PlannerCore;
use microrobot_planner::program::ProgramRunner;
use microrobot_runtime::PipelineConfig;
use microrobot_runtime::config::OwnedSection as _;

/// One publisher per stream, as a single planner, dynamics and actuator give.
const PUBLISHER: u128 = 1;

/// What one tick of the loop put on the bus.
#[derive(Debug, Clone, Copy)]
pub struct TickOutput {
    /// Setpoint k.
    pub setpoint: JointSetpoint,
    /// Torque k (`None`: dynamics refused the setpoint and the actuator held).
    pub torque: Option<TorqueCommand>,
    /// The state after the plant step: state k+1.
    pub state: JointState,
}

/// The pipeline's lockstep loop, in process.
pub struct ClosedLoop {
    planner: PlannerCore,
    dynamics: DynamicsCore,
    actuator: ActuatorCore<SimArm>,
    /// The state the next tick answers.
    state: JointState,
    now_ns: u64,
    period_ns: u64,
    /// The first tick answers the initial state without a state check (as the planner
    /// service does right after it starts).
    first: bool,
}

impl ClosedLoop {
    /// The loop of `cfg` (which must be a lockstep config: a free-running pipeline's
    /// streams depend on wall-clock timing and cannot be reproduced).
    pub fn new(cfg: &PipelineConfig) -> Result<Self> {
        if !cfg.lockstep {
            bail!(
                "closed-loop replay needs a lockstep run (`lockstep = true`): a free-running \
                 pipeline's streams depend on when each process woke up"
            );
        }
        let robot = microrobot_planner::load_robot(cfg)?;
        let program = match &cfg.program {
            Some(p) => Some(
                ProgramRunner::from_file(p, &robot)
                    .map_err(|e| anyhow!("program {}: {e}", p.display()))?,
            ),
            None => None,
        };
        let actuator_cfg = ActuatorConfig::from_pipeline(cfg)?;
        let sim = SimArm::new(
            &robot,
            &actuator_cfg.sim,
            &initial_q(&robot, &actuator_cfg.sim),
        );
        let mut actuator = ActuatorCore::new(sim, &robot, cfg, &actuator_cfg)
            .map_err(|e| anyhow!("simulated arm: {e}"))
            .context("closed-loop replay")?;
        let period_ns = cfg.period_ns();
        // Any start works: in lockstep, time only stamps messages and feeds the
        // watchdogs, which a loop without stalls keeps fresh.
        let now_ns = period_ns;
        let state = actuator.state_message(now_ns);
        let mut planner = PlannerCore::new(&robot, cfg, program);
        planner.accept_state(&state, PUBLISHER, now_ns);
        Ok(Self {
            planner,
            dynamics: DynamicsCore::new(&robot, cfg, &DynamicsConfig::from_pipeline(cfg)?),
            actuator,
            state,
            now_ns,
            period_ns,
            first: true,
        })
    }

    /// The actuator's initial state (the one the first setpoint answers).
    pub fn initial_state(&self) -> JointState {
        self.state
    }

    /// One tick of the loop.
    pub fn tick(&mut self) -> TickOutput {
        let now = self.now_ns;
        let _ = self.dynamics.accept_state(&self.state, PUBLISHER, now);
        if !std::mem::take(&mut self.first) {
            self.planner.check_state(now);
        }
        let setpoint = self.planner.tick(now);
        let torque = self.dynamics.compute(&setpoint, PUBLISHER, now).ok();
        if let Some(t) = &torque {
            let _ = self.actuator.accept_torque(t, PUBLISHER, now);
        }
        self.actuator.check_watchdog(now);
        let state = self.actuator.step(now);
        // The planner sees state k+1 as it arrives (the service accepts it on its event
        // and ticks right away).
        self.planner.accept_state(&state, PUBLISHER, now);
        self.state = state;
        self.now_ns += self.period_ns;
        TickOutput {
            setpoint,
            torque,
            state,
        }
    }
}

/// The compared content of a message: `(field, bits)` pairs, time stamps excluded (they
/// are wall-clock readings of the run).
fn content<const N: usize>(
    fixed: [(&'static str, u64); N],
    arrays: &[(&'static str, &[f64])],
    dof: u32,
) -> Vec<(String, u64)> {
    let n = (dof as usize).min(microrobot_messages::MAX_JOINTS);
    let mut v: Vec<(String, u64)> = fixed.iter().map(|(k, x)| (k.to_string(), *x)).collect();
    for (name, a) in arrays {
        for (j, x) in a.iter().take(n).enumerate() {
            v.push((format!("{name}[{}]", j + 1), x.to_bits()));
        }
    }
    v
}

/// A setpoint's compared fields.
pub fn setpoint_content(m: &JointSetpoint) -> Vec<(String, u64)> {
    content(
        [
            ("seq", m.header.seq),
            ("tick", m.header.tick),
            ("dof", m.dof.into()),
            ("flags", m.flags.into()),
        ],
        &[
            ("q", &m.q),
            ("qd", &m.qd),
            ("qdd", &m.qdd),
            ("jerk", &m.jerk),
        ],
        m.dof,
    )
}

/// A torque command's compared fields.
pub fn torque_content(m: &TorqueCommand) -> Vec<(String, u64)> {
    content(
        [
            ("seq", m.header.seq),
            ("tick", m.header.tick),
            ("setpoint_seq", m.setpoint_seq),
            ("state_seq", m.state_seq),
            ("dof", m.dof.into()),
            ("flags", m.flags.into()),
        ],
        &[("tau", &m.tau), ("q_desired", &m.q_desired)],
        m.dof,
    )
}

/// A measured state's compared fields.
pub fn state_content(m: &JointState) -> Vec<(String, u64)> {
    content(
        [
            ("seq", m.header.seq),
            ("tick", m.header.tick),
            ("torque_seq", m.torque_seq),
            ("dof", m.dof.into()),
            ("lifecycle", m.lifecycle.into()),
            ("flags", m.flags.into()),
        ],
        &[("q", &m.q), ("qd", &m.qd), ("tau_applied", &m.tau_applied)],
        m.dof,
    )
}

/// The first field in which `recorded` and `replayed` differ, in words.
pub fn first_difference(
    what: &str,
    recorded: &[(String, u64)],
    replayed: &[(String, u64)],
) -> Option<String> {
    if recorded.len() != replayed.len() {
        return Some(format!(
            "{what}: {} compared fields recorded, {} replayed",
            recorded.len(),
            replayed.len()
        ));
    }
    recorded
        .iter()
        .zip(replayed)
        .find(|(a, b)| a != b)
        .map(|((k, a), (_, b))| {
            if k.contains('[') {
                format!(
                    "{what}: {k} recorded {:e}, replayed {:e}",
                    f64::from_bits(*a),
                    f64::from_bits(*b)
                )
            } else {
                format!("{what}: {k} recorded {a}, replayed {b}")
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn config(lockstep: bool) -> PipelineConfig {
        let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
        let text = format!(
            "robot = \"config/robots/seed-arm.toml\"\nprogram = \"config/programs/seed-table4.toml\"\nlockstep = {lockstep}\n"
        );
        match microrobot_config::from_toml_str(&text, "test.toml", root) {
            Ok(c) => c,
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn a_free_running_config_is_refused() {
        let e = ClosedLoop::new(&config(false)).err().map(|e| e.to_string());
        assert!(e.is_some_and(|e| e.contains("lockstep")));
    }

    #[test]
    fn the_loop_is_deterministic_and_tracks_the_program() {
        let run = || {
            let mut l = match ClosedLoop::new(&config(true)) {
                Ok(l) => l,
                Err(e) => panic!("{e:#}"),
            };
            (0..3000).map(|_| l.tick()).collect::<Vec<_>>()
        };
        let (a, b) = (run(), run());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(state_content(&x.state), state_content(&y.state));
        }
        // Sequence numbers follow the ticks; each torque answers its setpoint and the
        // state before it, and the arm follows the setpoints closely.
        let mut worst: f64 = 0.0;
        for (k, o) in a.iter().enumerate() {
            let t = o.torque.unwrap_or_else(|| panic!("tick {k}: no torque"));
            assert_eq!(o.setpoint.header.seq, k as u64 + 1);
            assert_eq!(t.setpoint_seq, o.setpoint.header.seq);
            assert_eq!(t.state_seq, o.state.header.seq - 1);
            for j in 0..6 {
                worst = worst.max((o.state.q[j] - o.setpoint.q[j]).abs());
            }
        }
        let moved = (a[2999].setpoint.q[0] - a[0].setpoint.q[0]).abs();
        assert!(moved > 0.5, "the program moves joint 1: {moved} rad");
        assert!(worst < 1e-3, "tracking error {worst} rad");
    }
}
