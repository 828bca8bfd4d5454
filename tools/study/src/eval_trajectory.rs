//! `microrobot eval trajectory`: the trajectory library's machine interface.
//!
//! Reads JSON lines on stdin, one problem each (SI units):
//! `{"profile": "cubic"|"quintic"|"lspb"|"soft", "q0", "q1", "duration", "v0", "v1",
//! "a0", "a1", "cruise_velocity", "vmax", "amax", "jmax", "times": [t, ...]}` and writes
//! one JSON line per input, in order: `{"duration", "q", "qd", "qdd", "jerk"}` sampled
//! at `times`, or `{"error": "..."}` naming the field; the next line is processed
//! either way (an optional `"id"` is echoed back). When any per-joint field is an
//! array the line is one synchronised multi-joint problem (scalars apply to every
//! joint) and the samples come back indexed `[time][joint]`.

use std::io::{BufRead, Write};

use microrobot_trajectory::{
    JointVector, KinematicLimits, MAX_JOINTS, MotionRequest, MotionState, Profile, Trajectory,
    TrajectoryError,
};
use serde_json::{Map, Value, json};

/// Fields a problem may carry.
const FIELDS: [&str; 14] = [
    "profile",
    "q0",
    "q1",
    "duration",
    "v0",
    "v1",
    "a0",
    "a1",
    "cruise_velocity",
    "vmax",
    "amax",
    "jmax",
    "times",
    "id",
];

/// Per-joint fields that may be scalars or arrays.
const PER_JOINT: [&str; 10] = [
    "q0",
    "q1",
    "v0",
    "v1",
    "a0",
    "a1",
    "cruise_velocity",
    "vmax",
    "amax",
    "jmax",
];

/// Stands in for "no limit" where a profile ignores a limit (positions, or v/a/j of
/// fixed-duration profiles when not given).
const UNBOUNDED: f64 = 1e300;

/// Reads problems from stdin and answers each on stdout, one line per problem.
pub fn run() -> anyhow::Result<()> {
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let (mut lines, mut refused) = (0usize, 0usize);
    for line in stdin.lock().lines() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        lines += 1;
        let answer = eval_line(&line);
        if answer.starts_with("{\"error\"") {
            refused += 1;
        }
        writeln!(out, "{answer}")?;
        out.flush()?;
    }
    if refused > 0 {
        return Err(RefusedLines { refused, lines }.into());
    }
    Ok(())
}

/// Some input lines were answered with an error line: the job did not fully happen, so
/// the command fails once every line is answered (the CLI exits `JOB_FAILED`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RefusedLines {
    /// Lines answered with an error.
    pub refused: usize,
    /// Non-empty input lines.
    pub lines: usize,
}

impl std::fmt::Display for RefusedLines {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} input line(s) could not be evaluated (their output lines say why)",
            self.refused, self.lines
        )
    }
}

impl std::error::Error for RefusedLines {}

/// Answers one problem line (a JSON object) with one JSON line.
pub fn eval_line(line: &str) -> String {
    let answer = match serde_json::from_str::<Value>(line) {
        Ok(Value::Object(map)) => eval(&map).unwrap_or_else(|e| json!({ "error": e })),
        Ok(_) => json!({ "error": "problem: expected a JSON object" }),
        Err(e) => json!({ "error": format!("problem: invalid JSON: {e}") }),
    };
    answer.to_string()
}

/// Number of joints: the length of the array fields (which must agree), else 1.
fn joint_count(map: &Map<String, Value>) -> Result<(usize, bool), String> {
    let mut n: Option<usize> = None;
    for key in PER_JOINT {
        if let Some(Value::Array(a)) = map.get(key) {
            match n {
                Some(m) if m != a.len() => {
                    return Err(format!(
                        "{key}: has {} values, other fields have {m}",
                        a.len()
                    ));
                }
                _ => n = Some(a.len()),
            }
        }
    }
    match n {
        Some(0) => Err("q0: arrays must not be empty".into()),
        Some(m) if m > MAX_JOINTS => Err(format!("q0: at most {MAX_JOINTS} joints, got {m}")),
        Some(m) => Ok((m, true)),
        None => Ok((1, false)),
    }
}

fn number(key: &str, v: &Value) -> Result<f64, String> {
    v.as_f64()
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("{key}: expected a finite number, got {v}"))
}

/// A per-joint field: scalar (every joint) or array; `None` when absent.
fn per_joint(
    map: &Map<String, Value>,
    key: &str,
    dof: usize,
) -> Result<Option<JointVector>, String> {
    let mut out = JointVector::zeros();
    match map.get(key) {
        None | Some(Value::Null) => return Ok(None),
        Some(Value::Array(a)) => {
            for (i, x) in a.iter().enumerate() {
                out[i] = number(&format!("{key}[{i}]"), x)?;
            }
        }
        Some(x) => {
            let x = number(key, x)?;
            for i in 0..dof {
                out[i] = x;
            }
        }
    }
    Ok(Some(out))
}

/// The JSON name of a library field.
fn json_field(field: &str) -> &str {
    match field {
        "start.q" => "q0",
        "start.qd" => "v0",
        "start.qdd" => "a0",
        "target.q" => "q1",
        "target.qd" => "v1",
        "target.qdd" => "a1",
        "limits.velocity" => "vmax",
        "limits.acceleration" => "amax",
        "limits.jerk" => "jmax",
        "profile.duration" | "profile.min_duration" => "duration",
        "profile.cruise_velocity" => "cruise_velocity",
        other => other,
    }
}

fn describe(e: &TrajectoryError, multi: bool) -> String {
    let (joint, field) = match e {
        TrajectoryError::NotFinite { joint, field, .. }
        | TrajectoryError::NotPositive { joint, field, .. }
        | TrajectoryError::OutOfRange { joint, field, .. }
        | TrajectoryError::PositionOverrun { joint, field, .. }
        | TrajectoryError::Unsupported { joint, field, .. } => (*joint, *field),
        TrajectoryError::BadDof(_) => (0, "q0"),
    };
    let name = json_field(field);
    if multi {
        format!("{name}[{joint}]: {e}")
    } else {
        format!("{name}: {e}")
    }
}

fn eval(map: &Map<String, Value>) -> Result<Value, String> {
    if let Some(k) = map.keys().find(|k| !FIELDS.contains(&k.as_str())) {
        return Err(format!("{k}: unknown field"));
    }
    let (dof, multi) = joint_count(map)?;
    let profile_name = map
        .get("profile")
        .and_then(Value::as_str)
        .ok_or("profile: required, one of \"cubic\", \"quintic\", \"lspb\", \"soft\"")?;
    let req_joint = |key: &str| -> Result<JointVector, String> {
        per_joint(map, key, dof)?.ok_or_else(|| format!("{key}: required"))
    };
    let opt_joint = |key: &str| -> Result<JointVector, String> {
        Ok(per_joint(map, key, dof)?.unwrap_or_else(JointVector::zeros))
    };
    let q0 = req_joint("q0")?;
    let q1 = req_joint("q1")?;
    let duration = match map.get("duration") {
        None | Some(Value::Null) => None,
        Some(v) => Some(number("duration", v)?),
    };
    let times: Vec<f64> = match map.get("times") {
        None => Vec::new(),
        Some(Value::Array(a)) => a
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let t = number(&format!("times[{i}]"), t)?;
                if t < 0.0 {
                    Err(format!("times[{i}]: negative time {t}"))
                } else {
                    Ok(t)
                }
            })
            .collect::<Result<_, _>>()?,
        Some(v) => return Err(format!("times: expected an array, got {v}")),
    };
    let soft = profile_name == "soft";
    let limit = |key: &str| -> Result<JointVector, String> {
        match per_joint(map, key, dof)? {
            Some(v) => Ok(v),
            None if soft => Err(format!("{key}: required for soft motion")),
            None => Ok(JointVector::repeat(UNBOUNDED)),
        }
    };
    let need_duration = || duration.ok_or_else(|| format!("duration: required for {profile_name}"));
    let profile = match profile_name {
        "cubic" => Profile::Cubic {
            duration: need_duration()?,
        },
        "quintic" => Profile::Quintic {
            duration: need_duration()?,
        },
        "lspb" => Profile::Lspb {
            duration: need_duration()?,
            cruise_velocity: per_joint(map, "cruise_velocity", dof)?,
        },
        "soft" => Profile::Soft {
            min_duration: duration,
        },
        other => {
            return Err(format!(
                "profile: unknown profile {other:?}, expected \"cubic\", \"quintic\", \"lspb\" or \"soft\""
            ));
        }
    };
    if !matches!(profile, Profile::Lspb { .. }) && map.contains_key("cruise_velocity") {
        return Err("cruise_velocity: only for lspb".into());
    }
    let req = MotionRequest {
        dof,
        start: MotionState {
            q: q0,
            qd: opt_joint("v0")?,
            qdd: opt_joint("a0")?,
        },
        target: MotionState {
            q: q1,
            qd: opt_joint("v1")?,
            qdd: opt_joint("a1")?,
        },
        profile,
        limits: KinematicLimits {
            velocity: limit("vmax")?,
            acceleration: limit("amax")?,
            jerk: limit("jmax")?,
            position_min: JointVector::repeat(-UNBOUNDED),
            position_max: JointVector::repeat(UNBOUNDED),
        },
    };
    if soft {
        for key in ["v1", "a1"] {
            if per_joint(map, key, dof)?.is_some_and(|v| v.iter().take(dof).any(|x| *x != 0.0)) {
                return Err(format!("{key}: soft motion ends at rest"));
            }
        }
    }
    let tr = Trajectory::plan(&req).map_err(|e| describe(&e, multi))?;
    let mut cols: [Vec<Value>; 4] = Default::default();
    for &t in &times {
        let s = tr.sample(t);
        for (col, v) in cols.iter_mut().zip([s.q, s.qd, s.qdd, s.jerk]) {
            col.push(if multi {
                Value::from(v.iter().take(dof).copied().collect::<Vec<f64>>())
            } else {
                Value::from(v[0])
            });
        }
    }
    let [q, qd, qdd, jerk] = cols;
    let mut out = json!({ "duration": tr.duration(), "q": q, "qd": qd, "qdd": qdd, "jerk": jerk });
    if let Some(id) = map.get("id") {
        out["id"] = id.clone();
    }
    Ok(out)
}
