//! The state a restarted actuator resumes from: the last [`JointState`] its dead
//! predecessor published, handed over by the supervisor in the environment variable
//! [`RESUME_ENV`] (the physical arm does not teleport when its driver restarts).
//!
//! Format (SI, shortest round-trip floats, `dof` values each):
//! `q=0.1,0.2,...;qd=0.0,...;tau=1.5,...`. The velocity is the last measured one (not
//! zero): the arm was moving when its driver died. Validated before anything moves:
//! finite, the robot's joint count, q within the position limits (± [`POSITION_TOL`]),
//! |qd| ≤ the velocity limit × [`VELOCITY_FACTOR`], |τ| ≤ the torque limit.

use microrobot_messages::JointState;
use microrobot_model::{JointVector, Robot};

/// The environment variable carrying the resume state.
pub const RESUME_ENV: &str = "MICROROBOT_RESUME_STATE";

/// Tolerance on the position limits (rad or m): a tracking arm may overshoot a limit
/// it is planned to reach by its tracking error.
pub const POSITION_TOL: f64 = 1e-2;

/// A measured velocity may exceed the planned limit by the tracking error's rate.
pub const VELOCITY_FACTOR: f64 = 1.5;

/// A validated resume state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResumeState {
    pub q: JointVector,
    pub qd: JointVector,
    /// Torque the predecessor applied last: the new one blends from it.
    pub tau: JointVector,
}

fn list(v: &[f64]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// Encodes the active joints of `s` for [`RESUME_ENV`].
pub fn encode(s: &JointState) -> String {
    let n = (s.dof as usize).min(microrobot_messages::MAX_JOINTS);
    format!(
        "q={};qd={};tau={}",
        list(&s.q[..n]),
        list(&s.qd[..n]),
        list(&s.tau_applied[..n])
    )
}

impl ResumeState {
    /// Parses and validates `text` against `robot`; the error names the field and joint.
    pub fn parse(text: &str, robot: &Robot) -> Result<Self, String> {
        let dof = robot.dof();
        let mut fields: [Option<JointVector>; 3] = [None, None, None];
        for part in text.split(';') {
            let (key, values) = part
                .split_once('=')
                .ok_or_else(|| format!("`{part}` is not key=values"))?;
            let slot = match key.trim() {
                "q" => 0,
                "qd" => 1,
                "tau" => 2,
                other => return Err(format!("unknown field `{other}` (q, qd, tau)")),
            };
            let vals: Vec<&str> = values.split(',').collect();
            if vals.len() != dof {
                return Err(format!(
                    "{key} has {} values, the robot `{}` has {dof} joints",
                    vals.len(),
                    robot.name()
                ));
            }
            let mut v = JointVector::zeros();
            for (i, s) in vals.iter().enumerate() {
                let x: f64 = s
                    .trim()
                    .parse()
                    .map_err(|_| format!("{key}[{i}] = `{s}` is not a number"))?;
                if !x.is_finite() {
                    return Err(format!("{key}[{i}] is not finite"));
                }
                v[i] = x;
            }
            fields[slot] = Some(v);
        }
        let [Some(q), Some(qd), Some(tau)] = fields else {
            return Err("needs all of q, qd and tau".to_string());
        };
        for (i, j) in robot.joints().iter().enumerate() {
            let l = &j.limits;
            if q[i] < l.min - POSITION_TOL || q[i] > l.max + POSITION_TOL {
                return Err(format!(
                    "q[{i}] = {} is outside joint {}'s limits [{}, {}]",
                    q[i], j.name, l.min, l.max
                ));
            }
            if qd[i].abs() > l.velocity * VELOCITY_FACTOR {
                return Err(format!(
                    "qd[{i}] = {} exceeds joint {}'s velocity limit {} × {VELOCITY_FACTOR}",
                    qd[i], j.name, l.velocity
                ));
            }
            if tau[i].abs() > l.effort * (1.0 + 1e-9) {
                return Err(format!(
                    "tau[{i}] = {} exceeds joint {}'s torque limit {}",
                    tau[i], j.name, l.effort
                ));
            }
        }
        Ok(Self { q, qd, tau })
    }

    /// Reads [`RESUME_ENV`]: `Ok(None)` when it is not set.
    pub fn from_env(robot: &Robot) -> Result<Option<Self>, String> {
        match std::env::var(RESUME_ENV) {
            Ok(text) if !text.trim().is_empty() => Self::parse(&text, robot)
                .map(Some)
                .map_err(|e| format!("{RESUME_ENV}: {e}")),
            _ => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot() -> Robot {
        let text = r#"
[robot]
name = "two"
gravity_mps2 = [0.0, -9.81, 0.0]
[[joints]]
name = "j1"
kind = "revolute"
dh = { theta_deg = 0.0, d_mm = 0.0, a_mm = 500.0, alpha_deg = 0.0 }
limits = { min_deg = -90.0, max_deg = 90.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 20.0 }
link = { mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }
[[joints]]
name = "j2"
kind = "revolute"
dh = { theta_deg = 0.0, d_mm = 0.0, a_mm = 500.0, alpha_deg = 0.0 }
limits = { min_deg = -90.0, max_deg = 90.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 20.0 }
link = { mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }
"#;
        Robot::from_toml_str(text, "two.toml").unwrap()
    }

    #[test]
    fn encode_then_parse_round_trips_bit_for_bit() {
        let mut s = JointState {
            dof: 2,
            ..Default::default()
        };
        s.q[..2].copy_from_slice(&[0.1234567890123, -1.0 / 3.0]);
        s.qd[..2].copy_from_slice(&[0.5, -0.25]);
        s.tau_applied[..2].copy_from_slice(&[3.5, -19.0]);
        let r = ResumeState::parse(&encode(&s), &robot()).unwrap();
        assert_eq!(r.q[0], s.q[0]);
        assert_eq!(r.q[1], s.q[1]);
        assert_eq!(r.qd[1], s.qd[1]);
        assert_eq!(r.tau[1], s.tau_applied[1]);
    }

    #[test]
    fn bad_states_are_refused_naming_the_field() {
        let r = robot();
        let cases = [
            ("q=0.1;qd=0,0;tau=0,0", "q has 1 values"),
            ("q=0.1,NaN;qd=0,0;tau=0,0", "q[1] is not finite"),
            ("q=0.1,x;qd=0,0;tau=0,0", "q[1] = `x`"),
            ("q=0.1,2.0;qd=0,0;tau=0,0", "q[1] = 2 is outside"),
            ("q=0,0;qd=0,3.0;tau=0,0", "qd[1] = 3 exceeds"),
            ("q=0,0;qd=0,0;tau=25,0", "tau[0] = 25 exceeds"),
            ("q=0,0;qd=0,0", "needs all of q, qd and tau"),
            ("q=0,0;v=0,0;tau=0,0", "unknown field `v`"),
        ];
        for (text, want) in cases {
            let e = ResumeState::parse(text, &r).unwrap_err();
            assert!(e.contains(want), "{text}: {e}");
        }
    }
}
