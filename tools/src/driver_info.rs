//! `driver.toml`: everything an actuator driver needs to know about the run, resolved by
//! the supervisor into one flat file beside the resolved config, whatever the robot's
//! description (DH TOML, URDF, overlay): the instance, rate, lockstep, the watchdog and
//! hold-law settings, and per joint its name, kind, limits and start position, in SI
//! with the unit in each key (`_rad`/`_m`, `_rad_s`/`_m_s`, `_nm`/`_n`). A driver reads
//! it from `MICROROBOT_DRIVER_INFO` (or the `{driver_info}` placeholder) and needs no
//! robot-file parser of its own. The services do not read it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use microrobot_model::{JointKind, Robot};
use microrobot_runtime::config::{PipelineConfig, SafeStateMode};

/// The environment variable naming the file.
pub const DRIVER_INFO_ENV: &str = "MICROROBOT_DRIVER_INFO";

/// Where the file goes: beside the resolved config, in the run's private directory.
pub fn path_beside(resolved: &Path) -> PathBuf {
    resolved.with_file_name("driver.toml")
}

/// A TOML string (quoted and escaped).
fn quoted(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A float as TOML: shortest round-trip form, infinities as `inf`.
fn num(x: f64) -> String {
    if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.to_string()
    } else if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{x:.1}")
    } else {
        format!("{x}")
    }
}

/// The file's text for `cfg` and its `robot`; `resolved` is the resolved config's path.
/// The start position is the configured one (`actuator.sim.initial_q_deg`, clamped into
/// the limits); a restarted driver gets the arm's last state in `MICROROBOT_RESUME_STATE`.
pub fn render(cfg: &PipelineConfig, robot: &Robot, resolved: &Path) -> String {
    let start = microrobot_actuator::initial_q(robot, cfg);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# What an actuator driver needs for this run, written by the supervisor.\n\
         # SI units, named in each key; a driver needs nothing else (the contract page of\n\
         # the messages crate describes every key)."
    );
    let _ = writeln!(s, "instance = {}", quoted(&cfg.instance));
    let _ = writeln!(s, "rate_hz = {}", num(cfg.rate_hz));
    let _ = writeln!(s, "lockstep = {}", cfg.lockstep);
    let _ = writeln!(s, "status_period_ms = {}", num(cfg.status_period_ms));
    let _ = writeln!(s, "config = {}", quoted(&resolved.display().to_string()));
    let _ = writeln!(s, "robot = {}", quoted(&cfg.robot.display().to_string()));
    let _ = writeln!(s, "robot_name = {}", quoted(robot.name()));
    let _ = writeln!(s, "dof = {}", robot.dof());
    let w = &cfg.watchdog;
    let _ = writeln!(s, "\n[watchdog]");
    let _ = writeln!(s, "stale_ms = {}", num(w.stale_ms));
    let _ = writeln!(s, "fault_ms = {}", num(w.fault_ms));
    let safe_state = match w.safe_state {
        SafeStateMode::Hold => "hold",
        SafeStateMode::Damp => "damp",
    };
    let _ = writeln!(s, "safe_state = {}", quoted(safe_state));
    let _ = writeln!(s, "auto_resume = {}", w.auto_resume);
    let _ = writeln!(s, "ramp_ms = {}", num(w.ramp_ms));
    let a = &cfg.actuator;
    let _ = writeln!(s, "\n[hold]");
    let _ = writeln!(s, "kp_per_s2 = {}", num(a.hold_kp_per_s2));
    let _ = writeln!(s, "kd_per_s = {}", num(a.hold_kd_per_s));
    let _ = writeln!(s, "torque_slope_ms = {}", num(a.torque_slope_ms));
    for (i, j) in robot.joints().iter().enumerate() {
        let l = &j.limits;
        let (pos, vel, acc, effort, kind) = match j.kind {
            JointKind::Revolute => ("rad", "rad_s", "rad_s2", "nm", "revolute"),
            JointKind::Prismatic => ("m", "m_s", "m_s2", "n", "prismatic"),
        };
        let _ = writeln!(s, "\n[[joints]]");
        let _ = writeln!(s, "name = {}", quoted(&j.name));
        let _ = writeln!(s, "kind = {}", quoted(kind));
        let _ = writeln!(s, "min_{pos} = {}", num(l.min));
        let _ = writeln!(s, "max_{pos} = {}", num(l.max));
        let _ = writeln!(s, "vel_{vel} = {}", num(l.velocity));
        let _ = writeln!(s, "acc_{acc} = {}", num(l.acceleration));
        let _ = writeln!(s, "effort_{effort} = {}", num(l.effort));
        let _ = writeln!(s, "start_{pos} = {}", num(l.clamp(start[i])));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot(file: &str) -> Robot {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config/robots")
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
        cfg.actuator.sim.initial_q_deg = Some(vec![90.0, 45.0, 400.0]);
        let t = parse(&render(
            &cfg,
            &r,
            Path::new("/run/x/pipeline.resolved.toml"),
        ));
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
        cfg.actuator.hold_kp_per_s2 = 123.0;
        cfg.instance = "we\"ird".to_string();
        let t = parse(&render(&cfg, &r, Path::new("/r/p.toml")));
        assert_eq!(t["instance"].as_str(), Some("we\"ird"));
        assert_eq!(t["watchdog"]["stale_ms"].as_float(), Some(12.5));
        assert_eq!(t["watchdog"]["safe_state"].as_str(), Some("damp"));
        assert_eq!(t["hold"]["kp_per_s2"].as_float(), Some(123.0));
        assert_eq!(t["robot_name"].as_str(), Some("seed-arm"));
        assert_eq!(t["joints"].as_array().map(Vec::len), Some(6));
    }
}
