//! `[dynamics]` of the pipeline file: the torque law's gains and switches, read from the
//! raw section the runtime hands out ([`PipelineConfig::section`]).

use microrobot_keypath::Range;
use microrobot_runtime::config::{ConfigError, OwnedSection, PipelineConfig};
use toml::Table;

/// `[dynamics]`.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicsConfig {
    /// Computed-torque feedback on the measured state (false: feed-forward RNEA only).
    pub feedback: bool,
    /// Predict the measured state one period ahead before the feedback (it is one period
    /// older than the setpoint).
    pub delay_compensation: bool,
    /// Position gain Kp (1/s²).
    pub kp_per_s2: f64,
    /// Velocity gain Kd (1/s).
    pub kd_per_s: f64,
    /// Minimum time for a commanded torque to change by the joint's full effort limit
    /// (ms); 0 = no slew limit.
    pub torque_slew_ms: f64,
}

impl Default for DynamicsConfig {
    /// The built-in defaults (what an absent section gives).
    fn default() -> Self {
        Self {
            feedback: true,
            delay_compensation: true,
            kp_per_s2: 2500.0,
            kd_per_s: 100.0,
            torque_slew_ms: 20.0,
        }
    }
}

impl OwnedSection for DynamicsConfig {
    const NAME: &'static str = "dynamics";

    /// Reads `[dynamics]` of `cfg`: every key checked (unknown ones refused), absent ones
    /// defaulted, and the gains checked for discrete stability at `cfg.rate_hz`. Errors
    /// name the file and the key.
    fn from_pipeline(cfg: &PipelineConfig) -> Result<Self, ConfigError> {
        let t = cfg.section(Self::NAME)?;
        t.allow(&[
            "feedback",
            "delay_compensation",
            "kp_per_s2",
            "kd_per_s",
            "torque_slew_ms",
        ])?;
        let d = Self::default();
        let dynamics = Self {
            feedback: t.bool_or("feedback", d.feedback)?,
            delay_compensation: t.bool_or("delay_compensation", d.delay_compensation)?,
            kp_per_s2: t.number_in("kp_per_s2", d.kp_per_s2, Range::closed(0.0, 1.0e7))?,
            kd_per_s: t.number_in("kd_per_s", d.kd_per_s, Range::closed(0.0, 1.0e5))?,
            torque_slew_ms: t.number_in(
                "torque_slew_ms",
                d.torque_slew_ms,
                Range::closed(0.0, 10_000.0),
            )?,
        };
        // Discrete stability of the computed-torque loop at this rate (one-period delay).
        let rate_hz = cfg.rate_hz;
        if dynamics.kd_per_s / rate_hz > 1.0 || dynamics.kp_per_s2 / (rate_hz * rate_hz) > 0.5 {
            return Err(t
                .invalid(
                    "kp_per_s2",
                    format!(
                        "gains Kp {} /s², Kd {} /s are too high for {rate_hz} Hz (need Kd/rate <= 1, Kp/rate² <= 0.5)",
                        dynamics.kp_per_s2, dynamics.kd_per_s
                    ),
                )
                .into());
        }
        Ok(dynamics)
    }

    fn to_table(&self) -> Table {
        let mut t = Table::new();
        t.insert("feedback".into(), self.feedback.into());
        t.insert("delay_compensation".into(), self.delay_compensation.into());
        t.insert("kp_per_s2".into(), self.kp_per_s2.into());
        t.insert("kd_per_s".into(), self.kd_per_s.into());
        t.insert("torque_slew_ms".into(), self.torque_slew_ms.into());
        t
    }
}
