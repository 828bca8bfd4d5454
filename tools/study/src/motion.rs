//! The motion the study compares its four methods on, read from a motion program
//! file (the seed's Table 4: every joint from θi to θf, plus the quintic's boundary
//! accelerations).
//!
//! This reads the program TOML leniently (the format of config/programs/README.md
//! and a few aliases) and takes only what the study needs:
//! - the start position: `start_deg` (top level, under `[program]`, or `q_deg`
//!   under `[start]`); without one, the first target is the start;
//! - the target: the first entry of `[[segment]]` (or `segments`, `targets`, `moves`,
//!   `points`, `waypoints`) after the start, its position under `q_deg` /
//!   `target_deg` / `joints_deg` / `position_deg` — so the format of
//!   config/programs/README.md (a first segment to θi, then θi → θf) reads as the
//!   motion from its first target to its second;
//! - optional `[limits]` with `vel_deg_s`, `acc_deg_s2`, `jerk_deg_s3` (a number or
//!   one per joint), which override the robot file's kinematic limits;
//! - optional boundary accelerations for the quintic: `a0_deg_s2` / `a1_deg_s2`
//!   (also `start_acc_deg_s2` / `target_acc_deg_s2`), a number for all joints or one
//!   per joint, on the segment, under `[program]` or at the top level;
//! - optional `duration_s` of that segment (the program's own final time).
//!
//! Every `_deg` key above has the unit forms of config/programs/README.md, which
//! follow the joint type: `_deg`/`_rad` for revolute joints only, `_mm`/`_m` for
//! prismatic joints only, `_deg_mm`/`_rad_m` for each joint in its type's unit
//! (rates add `_s`, `_s2`, `_s3`). A unit that does not fit a joint's type is an
//! error naming the file, the key and the joint.

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use microrobot_model::{JointKind, JointVector};
use toml::{Table, Value};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Start and target of the studied motion, SI.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyMotion {
    /// Program name (from `name`, else the file stem).
    pub name: String,
    /// Start position (rad or m per joint type).
    pub start: JointVector,
    /// Target position (rad or m).
    pub target: JointVector,
    /// Quintic start acceleration (rad/s² or m/s²).
    pub start_acc: JointVector,
    /// Quintic target acceleration (rad/s² or m/s²).
    pub target_acc: JointVector,
    /// The segment's own duration (s), if the program gives one.
    pub duration: Option<f64>,
    /// The program's velocity, acceleration and jerk limits, if it overrides the robot's.
    pub limits: Option<[JointVector; 3]>,
}

const SEGMENT_LISTS: [&str; 7] = [
    "segment",
    "segments",
    "targets",
    "moves",
    "points",
    "waypoints",
    "steps",
];
const TARGET_KEYS: [&str; 6] = ["target", "q", "joints", "position", "q1", "theta_f"];
const START_KEYS: [&str; 4] = ["start", "q0", "initial", "theta_i"];
const A0_KEYS: [&str; 4] = ["a0", "start_acc", "acc_start", "qdd0"];
const A1_KEYS: [&str; 4] = ["a1", "target_acc", "acc_target", "qdd1"];
const DURATION_KEYS: [&str; 4] = ["duration_s", "tf_s", "final_time_s", "time_s"];

/// A unit family of key suffixes: name, and scale to SI for a revolute and a
/// prismatic joint (`None`: does not fit that type).
const UNITS: [(&str, Option<f64>, Option<f64>); 6] = [
    ("deg", Some(DEG), None),
    ("rad", Some(1.0), None),
    ("mm", None, Some(1e-3)),
    ("m", None, Some(1.0)),
    ("deg_mm", Some(DEG), Some(1e-3)),
    ("rad_m", Some(1.0), Some(1.0)),
];

/// The joints as the reader needs them: type and name.
pub type Joints<'a> = [(JointKind, &'a str)];

/// Reads `path` for a robot with `joints`; errors name the file and the key.
pub fn read(path: &Path, joints: &Joints) -> Result<StudyMotion> {
    let file = path.display().to_string();
    let text =
        std::fs::read_to_string(path).with_context(|| format!("{file}: cannot read program"))?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "program".into());
    parse(&text, &file, &stem, joints)
}

/// Parses program text (see the module documentation).
pub fn parse(text: &str, file: &str, stem: &str, joints: &Joints) -> Result<StudyMotion> {
    let dof = joints.len();
    let root: Table = text
        .parse()
        .map_err(|e: toml::de::Error| anyhow!("{file}: invalid TOML: {}", e.to_string().trim()))?;
    let program = root.get("program").and_then(Value::as_table);
    let scopes: Vec<(&str, &Table)> = std::iter::once(("", &root))
        .chain(program.map(|p| ("program.", p)))
        .collect();
    let name = scopes
        .iter()
        .find_map(|(_, t)| t.get("name").and_then(Value::as_str))
        .unwrap_or(stem)
        .to_string();

    // Segment list: at the top level or under [program].
    let mut segments: Vec<(String, &Table)> = Vec::new();
    for (prefix, t) in &scopes {
        for list in SEGMENT_LISTS {
            if let Some(arr) = t.get(list).and_then(Value::as_array) {
                for (i, v) in arr.iter().enumerate() {
                    let seg = v
                        .as_table()
                        .ok_or_else(|| anyhow!("{file}: {prefix}{list}[{i}]: expected a table"))?;
                    segments.push((format!("{prefix}{list}[{i}]"), seg));
                }
            }
        }
    }

    // Explicit start.
    let mut start = None;
    for (prefix, t) in &scopes {
        if let Some(v) = angles(t, &START_KEYS, prefix, file, joints)? {
            start = Some(v);
            break;
        }
        if let Some(st) = t.get("start").and_then(Value::as_table)
            && let Some(v) = angles(st, &["q"], &format!("{prefix}start."), file, joints)?
        {
            start = Some(v);
            break;
        }
    }
    let mut targets = Vec::new();
    for (key, seg) in &segments {
        if let Some(q) = angles(seg, &TARGET_KEYS, &format!("{key}."), file, joints)? {
            targets.push((key.clone(), *seg, q));
        }
    }
    if targets.is_empty() {
        for (prefix, t) in &scopes {
            if let Some(q) = angles(t, &["target"], prefix, file, joints)? {
                targets.push((format!("{prefix}target"), *t, q));
                break;
            }
        }
    }
    let (start, (seg_key, seg, target)) = match start {
        Some(s) => {
            let first = targets.into_iter().next().ok_or_else(|| {
                anyhow!("{file}: no target: expected [[segments]] with target_deg = [...] (one value per joint)")
            })?;
            (s, first)
        }
        None => {
            if targets.len() < 2 {
                bail!(
                    "{file}: no start: expected start_deg = [...] (or two targets: the first is the start)"
                );
            }
            let mut it = targets.into_iter();
            let first = it.next().map(|t| t.2).unwrap_or_default();
            let second = it
                .next()
                .ok_or_else(|| anyhow!("{file}: no second target"))?;
            (first, second)
        }
    };

    // Boundary accelerations and duration: segment first, then [program], then top.
    let seg_scope = [(format!("{seg_key}."), seg)];
    let all_scopes: Vec<(String, &Table)> = seg_scope
        .into_iter()
        .chain(scopes.iter().map(|(p, t)| (p.to_string(), *t)))
        .collect();
    let mut start_acc = JointVector::zeros();
    let mut target_acc = JointVector::zeros();
    for (p, t) in all_scopes.iter().rev() {
        if let Some(a) = accelerations(t, &A0_KEYS, p, file, joints)? {
            start_acc = a;
        }
        if let Some(a) = accelerations(t, &A1_KEYS, p, file, joints)? {
            target_acc = a;
        }
    }
    let mut duration = None;
    for (p, t) in &all_scopes {
        if let Some((k, v)) = DURATION_KEYS.iter().find_map(|k| t.get(*k).map(|v| (k, v))) {
            let d = number(v).ok_or_else(|| anyhow!("{file}: {p}{k}: expected a number"))?;
            if !(d > 0.0 && d.is_finite()) {
                bail!("{file}: {p}{k}: must be a positive finite number of seconds, got {d}");
            }
            duration = Some(d);
            break;
        }
    }
    let mut limits = None;
    for (p, t) in &scopes {
        let Some(l) = t.get("limits").and_then(Value::as_table) else {
            continue;
        };
        let prefix = format!("{p}limits.");
        let mut v = [JointVector::zeros(); 3];
        for (k, (base, order)) in [("vel", 1), ("acc", 2), ("jerk", 3)]
            .into_iter()
            .enumerate()
        {
            let x = vector(l, &[base], order, true, &prefix, file, joints)?
                .ok_or_else(|| anyhow!("{file}: {prefix}{base}_deg{}: missing", rate(order)))?;
            if let Some(i) = (0..dof).find(|&i| x[i] <= 0.0) {
                bail!("{file}: {prefix}{base}[{i}]: must be > 0");
            }
            v[k] = x;
        }
        limits = Some(v);
        break;
    }
    Ok(StudyMotion {
        name,
        start,
        target,
        start_acc,
        target_acc,
        duration,
        limits,
    })
}

fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Float(f) => Some(*f),
        Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// Key suffix of the `order`-th time derivative: "", "_s", "_s2", "_s3".
fn rate(order: usize) -> String {
    match order {
        0 => String::new(),
        1 => "_s".into(),
        n => format!("_s{n}"),
    }
}

/// A per-joint vector (the `order`-th time derivative of a position) under
/// `<base>_<unit><rate>` for a unit of [`UNITS`] (scalars broadcast when
/// `broadcast`), converted to SI; a unit that does not fit a joint's type is an error.
fn vector(
    t: &Table,
    bases: &[&str],
    order: usize,
    broadcast: bool,
    prefix: &str,
    file: &str,
    joints: &Joints,
) -> Result<Option<JointVector>> {
    let dof = joints.len();
    for base in bases {
        for (unit, rev, pri) in UNITS {
            let key = format!("{base}_{unit}{}", rate(order));
            let Some(v) = t.get(&key) else { continue };
            let mut scales = [1.0; microrobot_model::MAX_JOINTS];
            for (i, (kind, name)) in joints.iter().enumerate() {
                let (scale, is, fits) = match kind {
                    JointKind::Revolute => (rev, "revolute", "an angle: _deg, _rad or _deg_mm"),
                    JointKind::Prismatic => (pri, "prismatic", "a length: _mm, _m or _deg_mm"),
                };
                scales[i] = scale.ok_or_else(|| {
                    anyhow!(
                        "{file}: {prefix}{key}: joint {} (`{name}`) is {is}: give {fits} (each joint in its type's unit, see config/programs/README.md)",
                        i + 1
                    )
                })?;
            }
            let mut out = JointVector::zeros();
            match v {
                Value::Array(a) => {
                    if a.len() != dof {
                        bail!(
                            "{file}: {prefix}{key}: expected {dof} values (one per joint), got {}",
                            a.len()
                        );
                    }
                    for (i, x) in a.iter().enumerate() {
                        let x = number(x).ok_or_else(|| {
                            anyhow!("{file}: {prefix}{key}[{i}]: expected a number")
                        })?;
                        if !x.is_finite() {
                            bail!("{file}: {prefix}{key}[{i}]: {x} is not a finite number");
                        }
                        out[i] = x * scales[i];
                    }
                }
                other if broadcast => {
                    let x = number(other).filter(|x| x.is_finite()).ok_or_else(|| {
                        anyhow!("{file}: {prefix}{key}: expected a finite number or an array")
                    })?;
                    for i in 0..dof {
                        out[i] = x * scales[i];
                    }
                }
                _ => bail!("{file}: {prefix}{key}: expected an array of {dof} numbers"),
            }
            return Ok(Some(out));
        }
    }
    Ok(None)
}

fn angles(
    t: &Table,
    bases: &[&str],
    prefix: &str,
    file: &str,
    joints: &Joints,
) -> Result<Option<JointVector>> {
    vector(t, bases, 0, false, prefix, file, joints)
}

fn accelerations(
    t: &Table,
    bases: &[&str],
    prefix: &str,
    file: &str,
    joints: &Joints,
) -> Result<Option<JointVector>> {
    vector(t, bases, 2, true, prefix, file, joints)
}

#[cfg(test)]
mod tests {
    use super::*;

    const R: (JointKind, &str) = (JointKind::Revolute, "r");

    #[test]
    fn reads_start_target_and_quintic_accelerations() {
        let text = r#"
            [program]
            name = "t4"
            start_deg = [-180, -90]
            a0_deg_s2 = 5.0
            [[segments]]
            target_deg = [180.0, 90.0]
            profile = "quintic"
            duration_s = 5.0
            a1_deg_s2 = [-5.0, -4.0]
        "#;
        let m = parse(text, "p.toml", "p", &[R; 2]).unwrap();
        assert_eq!(m.name, "t4");
        assert!((m.start[0] + std::f64::consts::PI).abs() < 1e-15);
        assert!((m.target[1] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((m.start_acc[1] - 5.0 * DEG).abs() < 1e-15);
        assert!((m.target_acc[1] + 4.0 * DEG).abs() < 1e-15);
        assert_eq!(m.duration, Some(5.0));
    }

    #[test]
    fn reads_the_official_program_format_with_limits() {
        let text = r#"
            [program]
            name = "seed-table4"
            dof = 2
            [limits]
            vel_deg_s = [135.0, 70.0]
            acc_deg_s2 = 80.0
            jerk_deg_s3 = [160.0, 80.0]
            [[segment]]
            q_deg = [-180.0, -90.0]
            profile = "soft"
            [[segment]]
            q_deg = [180.0, 90.0]
            profile = "soft"
            duration_s = 5.0
        "#;
        let m = parse(text, "p.toml", "p", &[R; 2]).unwrap();
        assert!((m.start[1] + std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((m.target[0] - std::f64::consts::PI).abs() < 1e-15);
        assert_eq!(m.duration, Some(5.0));
        let l = m.limits.unwrap();
        assert!((l[1][1] - 80.0 * DEG).abs() < 1e-15);
        assert!((l[0][1] - 70.0 * DEG).abs() < 1e-15);
    }

    #[test]
    fn two_targets_without_start_use_the_first_as_start() {
        let text = "[[targets]]\nq_deg = [1.0]\n[[targets]]\nq_deg = [2.0]\n";
        let m = parse(text, "p.toml", "p", &[R; 1]).unwrap();
        assert!((m.start[0] - DEG).abs() < 1e-15);
        assert!((m.target[0] - 2.0 * DEG).abs() < 1e-15);
    }

    #[test]
    fn wrong_joint_count_names_file_and_key() {
        let text = "start_deg = [1.0]\n[[segments]]\ntarget_deg = [2.0, 3.0]\n";
        let e = parse(text, "p.toml", "p", &[R; 2]).unwrap_err().to_string();
        assert!(e.contains("p.toml") && e.contains("start_deg"), "{e}");
    }

    #[test]
    fn prismatic_joints_take_lengths_and_refuse_angles() {
        let rrp = [R, R, (JointKind::Prismatic, "boom")];
        let text = "a0_deg_mm_s2 = 10.0\n[[segment]]\nq_deg_mm = [0.0, 90.0, 100.0]\n[[segment]]\nq_rad_m = [0.5, 1.0, 0.25]\n";
        let m = parse(text, "p.toml", "p", &rrp).unwrap();
        assert!((m.start[2] - 0.1).abs() < 1e-15);
        assert!((m.start[1] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((m.target[2] - 0.25).abs() < 1e-15);
        assert!((m.start_acc[2] - 0.01).abs() < 1e-15);
        assert!((m.start_acc[0] - 10.0 * DEG).abs() < 1e-15);
        let e = parse(
            "[[segment]]\nq_deg = [0.0, 90.0, 100.0]\n[[segment]]\nq_deg = [1.0, 1.0, 1.0]\n",
            "p.toml",
            "p",
            &rrp,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("p.toml") && e.contains("q_deg") && e.contains("joint 3 (`boom`)"),
            "{e}"
        );
    }
}
