//! `[actuator]` and `[actuator.sim]` of the pipeline file: the actuator's safe-state
//! gains and torque slope, the external driver that replaces it, and the simulated arm,
//! read from the raw section the runtime hands out ([`PipelineConfig::section`]).

use microrobot_keypath::Range;
use microrobot_runtime::config::{ConfigError, OwnedSection, PipelineConfig};
use toml::{Table, Value};

/// Numerical integrator of the simulated arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    /// Classic 4th-order Runge-Kutta on (q, qd) with the torque held constant.
    Rk4,
    /// Semi-implicit (symplectic) Euler: qd += qdd·h, then q += qd·h.
    SemiImplicitEuler,
}

impl Integrator {
    /// The config's name for it (`actuator.sim.integrator`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Rk4 => "rk4",
            Self::SemiImplicitEuler => "semi_implicit_euler",
        }
    }
}

/// Actuator backend kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    /// The simulated arm (forward dynamics of the robot model).
    Sim,
}

/// `[actuator.sim]`: the simulated arm.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Link masses and inertias multiplied by this (1.1 = links 10 % heavier than the model).
    pub mass_scale: f64,
    /// Extra viscous friction on every joint, unknown to the dynamics (N·m·s/rad).
    pub viscous_friction_nms: f64,
    /// Extra Coulomb friction on every joint, unknown to the dynamics (N·m).
    pub coulomb_friction_nm: f64,
    /// Standard deviation of Gaussian noise on measured positions (rad).
    pub sensor_noise_rad: f64,
    /// Standard deviation of Gaussian noise on measured velocities (rad/s).
    pub sensor_noise_rad_s: f64,
    /// Integrator.
    pub integrator: Integrator,
    /// Integrator substeps per plant step.
    pub substeps: u32,
    /// Seed of the noise generator (same seed, same noise).
    pub seed: u64,
    /// Initial joint positions (deg, or mm for prismatic joints); `None`: all zero
    /// (clamped into the joint limits). Converted to SI by [`crate::initial_q`].
    pub initial_q_deg: Option<Vec<f64>>,
}

impl Default for SimConfig {
    /// The built-in defaults (what an absent `[actuator.sim]` gives): the exact model,
    /// no friction, no noise, RK4.
    fn default() -> Self {
        Self {
            mass_scale: 1.0,
            viscous_friction_nms: 0.0,
            coulomb_friction_nm: 0.0,
            sensor_noise_rad: 0.0,
            sensor_noise_rad_s: 0.0,
            integrator: Integrator::Rk4,
            substeps: 1,
            seed: 1,
            initial_q_deg: None,
        }
    }
}

/// `[actuator]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatorConfig {
    /// Backend kind.
    pub backend: BackendKind,
    /// External driver process run by the supervisor in place of the actuator service
    /// (program and arguments); `None`: the built-in actuator service.
    pub command: Option<Vec<String>>,
    /// Safe-state hold gain (1/s²).
    pub hold_kp_per_s2: f64,
    /// Safe-state hold / damping gain (1/s).
    pub hold_kd_per_s: f64,
    /// Minimum time for the applied torque to change by the joint's full effort limit
    /// (ms), a drive's torque slope; 0 = none.
    pub torque_slope_ms: f64,
    /// How long one lifecycle hook of the backend (an `on_reset` that brings a bus up
    /// again, an `on_activate` that enables drives) may block the cycle (ms): the
    /// status says so before the hook, and the supervisor takes the actuator for hung
    /// only once it has been silent for longer.
    pub hook_budget_ms: f64,
    /// The simulated arm.
    pub sim: SimConfig,
}

impl Default for ActuatorConfig {
    /// The built-in defaults (what an absent section gives).
    fn default() -> Self {
        Self {
            backend: BackendKind::Sim,
            command: None,
            hold_kp_per_s2: 400.0,
            hold_kd_per_s: 40.0,
            torque_slope_ms: 10.0,
            hook_budget_ms: 5000.0,
            sim: SimConfig::default(),
        }
    }
}

impl OwnedSection for ActuatorConfig {
    const NAME: &'static str = "actuator";

    /// Reads `[actuator]` (and `[actuator.sim]`) of `cfg`: every key checked (unknown
    /// ones refused), absent ones defaulted. Errors name the file and the key.
    fn from_pipeline(cfg: &PipelineConfig) -> Result<Self, ConfigError> {
        let t = cfg.section(Self::NAME)?;
        t.allow(&[
            "backend",
            "command",
            "hold_kp_per_s2",
            "hold_kd_per_s",
            "torque_slope_ms",
            "hook_budget_ms",
            "sim",
        ])?;
        let da = Self::default();
        let backend = t.choice("backend", da.backend, &[("sim", BackendKind::Sim)])?;
        let command = match t.get("command") {
            None => None,
            Some(Value::Array(items)) => {
                let mut out = Vec::with_capacity(items.len());
                for (i, it) in items.iter().enumerate() {
                    match it {
                        Value::String(s) if !s.is_empty() => out.push(s.clone()),
                        _ => {
                            return Err(t
                                .invalid(&format!("command[{i}]"), "expected a non-empty string")
                                .into());
                        }
                    }
                }
                if out.is_empty() {
                    return Err(t.invalid("command", "must name a program").into());
                }
                Some(out)
            }
            Some(_) => return Err(t.invalid("command", "expected an array of strings").into()),
        };
        let hold_kp_per_s2 = t.number_in(
            "hold_kp_per_s2",
            da.hold_kp_per_s2,
            Range::closed(0.0, 1.0e7),
        )?;
        let hold_kd_per_s = t.number_in(
            "hold_kd_per_s",
            da.hold_kd_per_s,
            Range::left_open(0.0, 1.0e5),
        )?;
        let torque_slope_ms = t.number_in(
            "torque_slope_ms",
            da.torque_slope_ms,
            Range::closed(0.0, 10_000.0),
        )?;
        let hook_budget_ms = t.number_in(
            "hook_budget_ms",
            da.hook_budget_ms,
            Range::left_open(0.0, 600_000.0),
        )?;
        let s = t.section(
            "sim",
            &[
                "mass_scale",
                "viscous_friction_nms",
                "coulomb_friction_nm",
                "sensor_noise_rad",
                "sensor_noise_rad_s",
                "integrator",
                "substeps",
                "seed",
                "initial_q_deg",
            ],
        )?;
        let ds = &da.sim;
        let initial_q_deg = match s.get("initial_q_deg") {
            None => None,
            Some(Value::Array(items)) => {
                if items.is_empty() || items.len() > 8 {
                    return Err(s.invalid("initial_q_deg", "expected 1 to 8 numbers").into());
                }
                let mut out = Vec::with_capacity(items.len());
                for (i, it) in items.iter().enumerate() {
                    out.push(s.number_of(it, s.key(&format!("initial_q_deg[{i}]")))?);
                }
                Some(out)
            }
            Some(_) => {
                return Err(s
                    .invalid("initial_q_deg", "expected an array of numbers")
                    .into());
            }
        };
        let sim = SimConfig {
            mass_scale: s.number_in("mass_scale", ds.mass_scale, Range::closed(0.1, 10.0))?,
            viscous_friction_nms: s.number_in(
                "viscous_friction_nms",
                ds.viscous_friction_nms,
                Range::closed(0.0, 1.0e4),
            )?,
            coulomb_friction_nm: s.number_in(
                "coulomb_friction_nm",
                ds.coulomb_friction_nm,
                Range::closed(0.0, 1.0e4),
            )?,
            sensor_noise_rad: s.number_in(
                "sensor_noise_rad",
                ds.sensor_noise_rad,
                Range::closed(0.0, 1.0),
            )?,
            sensor_noise_rad_s: s.number_in(
                "sensor_noise_rad_s",
                ds.sensor_noise_rad_s,
                Range::closed(0.0, 10.0),
            )?,
            integrator: s.choice(
                "integrator",
                ds.integrator,
                &[
                    ("rk4", Integrator::Rk4),
                    ("semi_implicit_euler", Integrator::SemiImplicitEuler),
                ],
            )?,
            substeps: s.integer_in("substeps", ds.substeps as u64, 1, 1000)? as u32,
            seed: s.integer_in("seed", ds.seed, 0, i64::MAX as u64)?,
            initial_q_deg,
        };
        Ok(Self {
            backend,
            command,
            hold_kp_per_s2,
            hold_kd_per_s,
            torque_slope_ms,
            hook_budget_ms,
            sim,
        })
    }

    fn to_table(&self) -> Table {
        let mut t = Table::new();
        t.insert("backend".into(), "sim".into());
        if let Some(cmd) = &self.command {
            t.insert("command".into(), cmd.clone().into());
        }
        t.insert("hold_kp_per_s2".into(), self.hold_kp_per_s2.into());
        t.insert("hold_kd_per_s".into(), self.hold_kd_per_s.into());
        t.insert("torque_slope_ms".into(), self.torque_slope_ms.into());
        t.insert("hook_budget_ms".into(), self.hook_budget_ms.into());
        let m = &self.sim;
        let mut s = Table::new();
        s.insert("mass_scale".into(), m.mass_scale.into());
        s.insert("viscous_friction_nms".into(), m.viscous_friction_nms.into());
        s.insert("coulomb_friction_nm".into(), m.coulomb_friction_nm.into());
        s.insert("sensor_noise_rad".into(), m.sensor_noise_rad.into());
        s.insert("sensor_noise_rad_s".into(), m.sensor_noise_rad_s.into());
        s.insert("integrator".into(), m.integrator.name().into());
        s.insert("substeps".into(), i64::from(m.substeps).into());
        // The range keeps it within i64 (`seed` is at most i64::MAX).
        s.insert("seed".into(), (m.seed.min(i64::MAX as u64) as i64).into());
        if let Some(q) = &m.initial_q_deg {
            s.insert("initial_q_deg".into(), q.clone().into());
        }
        t.insert("sim".into(), Value::Table(s));
        t
    }
}
