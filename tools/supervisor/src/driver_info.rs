//! `driver.toml`: everything an actuator driver needs to know about the run, resolved by
//! the supervisor into one flat file beside the resolved config, whatever the robot's
//! description (DH TOML, URDF, overlay): the instance, rate, lockstep, the watchdog and
//! hold-law settings, and per joint its name, kind, limits and start position, in SI
//! with the unit in each key (`_rad`/`_m`, `_rad_s`/`_m_s`, `_nm`/`_n`). A driver reads
//! it from `MICROROBOT_DRIVER_INFO` (or the `{driver_info}` placeholder) and needs no
//! robot-file parser of its own. The services do not read it.

use std::path::{Path, PathBuf};

use microrobot_actuator::ActuatorConfig;
use microrobot_model::{JointKind, Robot};
use microrobot_runtime::config::{ConfigError, OwnedSection as _, PipelineConfig};
use toml::{Table, Value};

/// The environment variable naming the file.
pub const DRIVER_INFO_ENV: &str = "MICROROBOT_DRIVER_INFO";

/// Where the file goes: beside the resolved config, in the run's private directory.
pub fn path_beside(resolved: &Path) -> PathBuf {
    resolved.with_file_name("driver.toml")
}

/// The file's text for `cfg` and its `robot`; `resolved` is the resolved config's path.
/// The start position is the configured one (`actuator.sim.initial_q_deg`, clamped into
/// the limits); a restarted driver gets the arm's last state in `MICROROBOT_RESUME_STATE`.
/// Written with the `toml` crate, so names and numbers round-trip exactly.
pub fn render(cfg: &PipelineConfig, robot: &Robot, resolved: &Path) -> Result<String, ConfigError> {
    let a = &ActuatorConfig::from_pipeline(cfg)?;
    let start = microrobot_actuator::initial_q(robot, &a.sim);
    let path = |p: &Path| Value::String(p.display().to_string());
    let w = &cfg.watchdog;
    let watchdog = Table::from_iter([
        ("stale_ms".to_string(), Value::Float(w.stale_ms)),
        ("fault_ms".to_string(), Value::Float(w.fault_ms)),
        ("safe_state".to_string(), Value::from(w.safe_state.name())),
        ("auto_resume".to_string(), Value::Boolean(w.auto_resume)),
        ("ramp_ms".to_string(), Value::Float(w.ramp_ms)),
    ]);
    let hold = Table::from_iter([
        ("kp_per_s2".to_string(), Value::Float(a.hold_kp_per_s2)),
        ("kd_per_s".to_string(), Value::Float(a.hold_kd_per_s)),
        (
            "torque_slope_ms".to_string(),
            Value::Float(a.torque_slope_ms),
        ),
    ]);
    let joints = robot
        .joints()
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let l = &j.limits;
            let (pos, vel, acc, effort, kind) = match j.kind {
                JointKind::Revolute => ("rad", "rad_s", "rad_s2", "nm", "revolute"),
                JointKind::Prismatic => ("m", "m_s", "m_s2", "n", "prismatic"),
            };
            Value::Table(Table::from_iter([
                ("name".to_string(), Value::from(j.name.as_str())),
                ("kind".to_string(), Value::from(kind)),
                (format!("min_{pos}"), Value::Float(l.min)),
                (format!("max_{pos}"), Value::Float(l.max)),
                (format!("vel_{vel}"), Value::Float(l.velocity)),
                (format!("acc_{acc}"), Value::Float(l.acceleration)),
                (format!("effort_{effort}"), Value::Float(l.effort)),
                (format!("start_{pos}"), Value::Float(l.clamp(start[i]))),
            ]))
        })
        .collect();
    let file = Table::from_iter([
        ("instance".to_string(), Value::from(cfg.instance.as_str())),
        ("rate_hz".to_string(), Value::Float(cfg.rate_hz)),
        ("lockstep".to_string(), Value::Boolean(cfg.lockstep)),
        (
            "status_period_ms".to_string(),
            Value::Float(cfg.status_period_ms),
        ),
        ("config".to_string(), path(resolved)),
        ("robot".to_string(), path(&cfg.robot)),
        ("robot_name".to_string(), Value::from(robot.name())),
        ("dof".to_string(), Value::Integer(robot.dof() as i64)),
        ("watchdog".to_string(), Value::Table(watchdog)),
        ("hold".to_string(), Value::Table(hold)),
        ("joints".to_string(), Value::Array(joints)),
    ]);
    Ok(format!(
        "# What an actuator driver needs for this run, written by the supervisor.\n\
         # SI units, named in each key; a driver needs nothing else (the contract page of\n\
         # the messages crate describes every key).\n{file}"
    ))
}

/// Writes [`render`] beside the resolved config (owner-only, never through a symlink):
/// what `run` and `driver-check` hand a driver.
pub fn write(cfg: &PipelineConfig, robot: &Robot, resolved: &Path) -> anyhow::Result<()> {
    crate::instance::write_private(
        &path_beside(resolved),
        render(cfg, robot, resolved)?.as_bytes(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use microrobot_runtime::config::SafeStateMode;

    fn robot(file: &str) -> Robot {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/robots")
            .join(file);
        Robot::from_file(&path).expect("robot file")
    }

    fn parse(text: &str) -> toml::Table {
        text.parse::<toml::Table>().expect("driver.toml is TOML")
    }

    #[test]
    fn every_joint_in_si_with_its_unit_in_the_key() {
        let r = robot("spherical-rrp.toml");
        let mut cfg = PipelineConfig {
            rate_hz: 4000.0,
            lockstep: true,
            ..PipelineConfig::default()
        };
        // Revolute start in degrees, prismatic in mm; the prismatic one past its limit.
        let mut actuator = ActuatorConfig::default();
        actuator.sim.initial_q_deg = Some(vec![90.0, 45.0, 400.0]);
        actuator.store(&mut cfg);
        let t =
            parse(&render(&cfg, &r, Path::new("/run/x/pipeline.resolved.toml")).expect("render"));
        assert_eq!(t["rate_hz"].as_float(), Some(4000.0));
        assert_eq!(t["lockstep"].as_bool(), Some(true));
        assert_eq!(t["dof"].as_integer(), Some(3));
        assert_eq!(t["config"].as_str(), Some("/run/x/pipeline.resolved.toml"));
        let joints = t["joints"].as_array().expect("[[joints]]");
        assert_eq!(joints.len(), 3);
        let j0 = joints[0].as_table().expect("table");
        assert_eq!(j0["kind"].as_str(), Some("revolute"));
        let start = j0["start_rad"].as_float().expect("start_rad");
        assert!((start - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert_eq!(j0["effort_nm"].as_float(), Some(40.0));
        assert!(!j0.contains_key("start_m"));
        let j2 = joints[2].as_table().expect("table");
        assert_eq!(j2["kind"].as_str(), Some("prismatic"));
        assert_eq!(j2["max_m"].as_float(), Some(0.3));
        // 400 mm is clamped to the 300 mm limit.
        assert_eq!(j2["start_m"].as_float(), Some(0.3));
        assert_eq!(j2["effort_n"].as_float(), Some(200.0));
        assert!(!j2.contains_key("effort_nm"));
    }

    #[test]
    fn the_watchdog_and_the_hold_law_are_the_configs() {
        let r = robot("seed-arm.toml");
        let mut cfg = PipelineConfig::default();
        cfg.watchdog.stale_ms = 12.5;
        cfg.watchdog.safe_state = SafeStateMode::Damp;
        ActuatorConfig {
            hold_kp_per_s2: 123.0,
            ..ActuatorConfig::default()
        }
        .store(&mut cfg);
        cfg.instance = "we\"ird".to_string();
        let t = parse(&render(&cfg, &r, Path::new("/r/p.toml")).expect("render"));
        assert_eq!(t["instance"].as_str(), Some("we\"ird"));
        assert_eq!(t["watchdog"]["stale_ms"].as_float(), Some(12.5));
        assert_eq!(t["watchdog"]["safe_state"].as_str(), Some("damp"));
        assert_eq!(t["hold"]["kp_per_s2"].as_float(), Some(123.0));
        assert_eq!(t["robot_name"].as_str(), Some("seed-arm"));
        assert_eq!(t["joints"].as_array().map(Vec::len), Some(6));
    }
}
