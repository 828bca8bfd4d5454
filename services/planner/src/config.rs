//! `[teleop]` of the pipeline file: the planner's teleoperation mode (a master device
//! drives the arm), read from the raw section the runtime hands out
//! ([`PipelineConfig::section`]) and converted to SI.

use microrobot_keypath::Range;
use microrobot_runtime::config::{ConfigError, OwnedSection, PipelineConfig};
use toml::{Table, Value};

/// `[teleop]`, converted to SI at load.
#[derive(Debug, Clone, PartialEq)]
pub struct TeleopConfig {
    /// Start the planner in teleop mode (else `microrobot send teleop` enters it).
    pub enabled: bool,
    /// Hand displacement / tool displacement (3 = 3:1).
    pub ratio: f64,
    /// Orientation of the master device's frame in the robot's base frame: roll, pitch,
    /// yaw about fixed x, y, z (rad; `frame_rpy_deg` in the file).
    pub frame_rpy: [f64; 3],
    /// Tremor filter: Butterworth low-pass order (2, 4, 6, 8).
    pub filter_order: u32,
    /// Tremor filter cutoff (Hz).
    pub filter_cutoff_hz: f64,
    /// Tool speed limit (m/s; `max_tool_vel_mm_s`).
    pub max_tool_velocity: f64,
    /// Tool acceleration limit (m/s²; `max_tool_acc_mm_s2`).
    pub max_tool_acceleration: f64,
    /// No valid master sample for this long: the tool is brought to rest and held (ms).
    pub master_timeout_ms: f64,
    /// Smallest singular value of the position Jacobian below which the tool slows
    /// (m/rad; `singularity_sigma_mm` in mm/rad).
    pub singularity_sigma: f64,
    /// Largest joint change of one IK solution per cycle before it counts as a
    /// configuration flip and is refused (rad; `flip_threshold_deg`).
    pub flip_threshold: f64,
    /// IK residual above which the target is outside the workspace (m; `workspace_tolerance_mm`).
    pub workspace_tolerance: f64,
}

impl Default for TeleopConfig {
    /// The built-in defaults (what an absent section gives).
    fn default() -> Self {
        Self {
            enabled: false,
            ratio: 3.0,
            frame_rpy: [0.0; 3],
            filter_order: 4,
            filter_cutoff_hz: 4.0,
            max_tool_velocity: 0.05,
            max_tool_acceleration: 0.5,
            master_timeout_ms: 50.0,
            singularity_sigma: 0.01,
            flip_threshold: 2f64.to_radians(),
            workspace_tolerance: 1e-5,
        }
    }
}

impl OwnedSection for TeleopConfig {
    const NAME: &'static str = "teleop";

    /// Reads `[teleop]` of `cfg`: every key checked (unknown ones refused), absent ones
    /// defaulted, mm and deg converted to m and rad; the filter cutoff must lie below
    /// 0.45 × `cfg.rate_hz`. Errors name the file and the key.
    fn from_pipeline(cfg: &PipelineConfig) -> Result<Self, ConfigError> {
        let rate_hz = cfg.rate_hz;
        let t = cfg.section(Self::NAME)?;
        t.allow(&[
            "enabled",
            "ratio",
            "frame_rpy_deg",
            "filter_order",
            "filter_cutoff_hz",
            "max_tool_vel_mm_s",
            "max_tool_acc_mm_s2",
            "master_timeout_ms",
            "singularity_sigma_mm",
            "flip_threshold_deg",
            "workspace_tolerance_mm",
        ])?;
        let d = Self::default();
        let frame_rpy = match t.get("frame_rpy_deg") {
            None => d.frame_rpy,
            Some(Value::Array(items)) if items.len() == 3 => {
                let mut out = [0.0; 3];
                for (i, it) in items.iter().enumerate() {
                    let k = format!("frame_rpy_deg[{i}]");
                    let v = match it {
                        Value::Float(v) => *v,
                        Value::Integer(v) => *v as f64,
                        _ => return Err(t.invalid(&k, "expected a number").into()),
                    };
                    if !(v.is_finite() && v.abs() <= 360.0) {
                        return Err(t
                            .invalid(&k, format!("{v} must be a finite angle in [-360, 360] deg"))
                            .into());
                    }
                    out[i] = v.to_radians();
                }
                out
            }
            Some(_) => {
                return Err(t
                    .invalid(
                        "frame_rpy_deg",
                        "expected 3 numbers: roll, pitch, yaw (deg)",
                    )
                    .into());
            }
        };
        let filter_order = t.integer_in("filter_order", d.filter_order as u64, 2, 8)? as u32;
        if !filter_order.is_multiple_of(2) {
            return Err(t
                .invalid(
                    "filter_order",
                    format!("{filter_order} must be 2, 4, 6 or 8"),
                )
                .into());
        }
        let ms = 1e-3;
        Ok(Self {
            enabled: t.bool_or("enabled", d.enabled)?,
            ratio: t.number_in("ratio", d.ratio, Range::closed(0.1, 100.0))?,
            frame_rpy,
            filter_order,
            filter_cutoff_hz: t.number_in(
                "filter_cutoff_hz",
                d.filter_cutoff_hz,
                Range::left_open(0.0, 0.45 * rate_hz),
            )?,
            max_tool_velocity: t.number_in(
                "max_tool_vel_mm_s",
                d.max_tool_velocity / ms,
                Range::left_open(0.0, 10_000.0),
            )? * ms,
            max_tool_acceleration: t.number_in(
                "max_tool_acc_mm_s2",
                d.max_tool_acceleration / ms,
                Range::left_open(0.0, 1.0e6),
            )? * ms,
            master_timeout_ms: t.number_in(
                "master_timeout_ms",
                d.master_timeout_ms,
                Range::left_open(0.0, 60_000.0),
            )?,
            singularity_sigma: t.number_in(
                "singularity_sigma_mm",
                d.singularity_sigma / ms,
                Range::closed(0.0, 10_000.0),
            )? * ms,
            flip_threshold: t
                .number_in(
                    "flip_threshold_deg",
                    d.flip_threshold.to_degrees(),
                    Range::left_open(0.0, 180.0),
                )?
                .to_radians(),
            workspace_tolerance: t.number_in(
                "workspace_tolerance_mm",
                d.workspace_tolerance / ms,
                Range::left_open(0.0, 100.0),
            )? * ms,
        })
    }

    fn to_table(&self) -> Table {
        let mut t = Table::new();
        t.insert("enabled".into(), self.enabled.into());
        t.insert("ratio".into(), self.ratio.into());
        let rpy: Vec<f64> = self.frame_rpy.iter().map(|a| a.to_degrees()).collect();
        t.insert("frame_rpy_deg".into(), rpy.into());
        t.insert("filter_order".into(), i64::from(self.filter_order).into());
        t.insert("filter_cutoff_hz".into(), self.filter_cutoff_hz.into());
        t.insert(
            "max_tool_vel_mm_s".into(),
            (self.max_tool_velocity * 1e3).into(),
        );
        t.insert(
            "max_tool_acc_mm_s2".into(),
            (self.max_tool_acceleration * 1e3).into(),
        );
        t.insert("master_timeout_ms".into(), self.master_timeout_ms.into());
        t.insert(
            "singularity_sigma_mm".into(),
            (self.singularity_sigma * 1e3).into(),
        );
        t.insert(
            "flip_threshold_deg".into(),
            self.flip_threshold.to_degrees().into(),
        );
        t.insert(
            "workspace_tolerance_mm".into(),
            (self.workspace_tolerance * 1e3).into(),
        );
        t
    }
}
