//! Motion programs: a TOML list of targets with via points (format in
//! `config/programs/README.md`).
//!
//! [`Program::from_toml_str`] parses and checks a program (units converted once, unknown
//! keys refused). [`Program::plan_all`] plans every segment from the state where the
//! previous one hands over, so q and qd stay continuous, and qdd too where the next
//! profile takes a start acceleration (quintic, soft motion). [`ProgramRunner`] steps
//! the planned segments per cycle without allocating.

use microrobot_model::JointKind;
use serde::Deserialize;

use crate::{
    Generator, JointVector, KinematicLimits, MAX_JOINTS, MotionRequest, MotionState, Profile,
    Sample, Status, Trajectory, TrajectoryError,
};

/// A Cartesian target: tool position and orientation in the base frame (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CartesianPose {
    /// Position (m).
    pub xyz_m: [f64; 3],
    /// Roll, pitch, yaw about fixed x, y, z (rad).
    pub rpy_rad: [f64; 3],
}

/// Inverse kinematics as the program module needs it, so it does not depend on the
/// robot model's internals. `seed` is the previous target's joint positions.
pub trait CartesianSolver {
    /// Joint positions reaching `pose`, or why not.
    fn solve(&self, pose: &CartesianPose, seed: &JointVector) -> Result<JointVector, String>;
}

/// A solver for programs without Cartesian targets: refuses every pose.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoCartesian;

impl CartesianSolver for NoCartesian {
    fn solve(&self, _: &CartesianPose, _: &JointVector) -> Result<JointVector, String> {
        Err("no inverse kinematics available for Cartesian targets".into())
    }
}

/// Why a program could not be loaded or planned. `origin` is the file name (or
/// whatever the caller passed), `segment` the 0-based segment index.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProgramError {
    /// Not valid TOML, an unknown key, a missing key or a wrong type.
    #[error("{origin}: {message}")]
    Parse {
        /// Source of the text.
        origin: String,
        /// The parser's message (names the key).
        message: String,
    },
    /// A key with a bad value.
    #[error("{origin}: segment[{segment}].{key}: {message}")]
    Invalid {
        /// Source of the text.
        origin: String,
        /// Segment index (0 for program-wide keys).
        segment: usize,
        /// The key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The IK could not reach a Cartesian target.
    #[error("{origin}: segment[{segment}].pose: {message}")]
    Ik {
        /// Source of the text.
        origin: String,
        /// Segment index.
        segment: usize,
        /// The solver's reason.
        message: String,
    },
    /// The trajectory library refused the segment.
    #[error("{origin}: segment[{segment}]: {source}")]
    Plan {
        /// Source of the text.
        origin: String,
        /// Segment index.
        segment: usize,
        /// The planning error (names joint and field).
        source: TrajectoryError,
    },
}

/// Profile of a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProfileKind {
    /// Cubic polynomial over `duration_s`.
    Cubic,
    /// Quintic polynomial over `duration_s`.
    Quintic,
    /// Linear segment with parabolic blends over `duration_s` (stops at its target).
    Lspb,
    /// Time-optimal jerk-limited motion (stretched to `duration_s` if given).
    Soft,
}

/// What happens at a segment's target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum End {
    /// Come to rest at the target.
    Stop,
    /// Pass through: polynomials keep a via velocity; soft motion hands over to the
    /// next segment `blend` seconds before it would stop.
    Blend {
        /// Hand-over time before the end (soft motion), s.
        blend: Option<f64>,
    },
}

/// Where a segment goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// Joint positions (rad for revolute, m for prismatic joints).
    Joint(JointVector),
    /// Tool pose, through a [`CartesianSolver`].
    Cartesian(CartesianPose),
}

/// One segment of a program, in SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Optional label.
    pub name: Option<String>,
    /// Target.
    pub target: Target,
    /// Profile.
    pub profile: ProfileKind,
    /// Duration (s): required for cubic, quintic, LSPB; minimum for soft motion.
    pub duration: Option<f64>,
    /// LSPB cruise velocity per joint (rad/s).
    pub cruise_velocity: Option<JointVector>,
    /// Stop at or blend through the target.
    pub end: End,
}

/// A loaded motion program.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Program name.
    pub name: String,
    /// Number of joints.
    pub dof: usize,
    /// Optional overrides of the caller's velocity, acceleration and jerk limits.
    pub limits: Option<[JointVector; 3]>,
    /// Segments in order.
    pub segments: Vec<Segment>,
}

/// A planned segment: its trajectory and the time at which the next one takes over.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedSegment {
    /// The motion, from the previous segment's hand-over state.
    pub trajectory: Trajectory,
    /// Time (s, from this segment's start) at which the next segment starts.
    pub hand_over: f64,
}

// ---- TOML shape -------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    program: HeaderToml,
    limits: Option<LimitsToml>,
    segment: Vec<SegmentToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HeaderToml {
    name: String,
    dof: usize,
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Values {
    One(f64),
    Many(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LimitsToml {
    vel_deg_s: Values,
    acc_deg_s2: Values,
    jerk_deg_s3: Values,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseToml {
    xyz_mm: [f64; 3],
    rpy_deg: [f64; 3],
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum EndToml {
    Stop,
    Blend,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentToml {
    name: Option<String>,
    q_deg: Option<Vec<f64>>,
    q_rad: Option<Vec<f64>>,
    q_mm: Option<Vec<f64>>,
    q_m: Option<Vec<f64>>,
    q_deg_mm: Option<Vec<f64>>,
    q_rad_m: Option<Vec<f64>>,
    pose: Option<PoseToml>,
    profile: Option<ProfileKind>,
    duration_s: Option<f64>,
    cruise_vel_deg_s: Option<Values>,
    end: Option<EndToml>,
    blend_s: Option<f64>,
}

/// A joint-target key: its name and its scale to SI for a revolute and a prismatic
/// joint (`None`: the key's unit does not fit that joint type).
type TargetKey = (&'static str, Option<f64>, Option<f64>);

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Joint-target keys: one unit for every joint (`q_deg`, `q_rad`: revolute only;
/// `q_mm`, `q_m`: prismatic only) or each joint in its type's unit (`q_deg_mm`,
/// `q_rad_m`).
const TARGET_KEYS: [TargetKey; 6] = [
    ("q_deg", Some(DEG), None),
    ("q_rad", Some(1.0), None),
    ("q_mm", None, Some(1e-3)),
    ("q_m", None, Some(1.0)),
    ("q_deg_mm", Some(DEG), Some(1e-3)),
    ("q_rad_m", Some(1.0), Some(1.0)),
];

impl Program {
    /// Parses a program; `origin` names the source in errors (e.g. the file path).
    /// Without the robot's joint types, `q_deg`/`q_rad` are read as angles and
    /// `q_mm`/`q_m` as lengths, and `q_deg_mm` is refused; prefer
    /// [`Program::from_toml_str_for`].
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Program, ProgramError> {
        Self::parse(text, origin, None)
    }

    /// Parses a program for a robot whose joints have the types `kinds`: every unit
    /// must fit its joint's type (angles for revolute joints, lengths for prismatic
    /// ones); an error names the file, the segment, the key and the joint.
    pub fn from_toml_str_for(
        text: &str,
        origin: &str,
        kinds: &[JointKind],
    ) -> Result<Program, ProgramError> {
        Self::parse(text, origin, Some(kinds))
    }

    fn parse(
        text: &str,
        origin: &str,
        kinds: Option<&[JointKind]>,
    ) -> Result<Program, ProgramError> {
        let file: FileToml = toml::from_str(text).map_err(|e| ProgramError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        let dof = file.program.dof;
        let _ = file.program.description;
        let bad = |segment: usize, key: &'static str, message: String| ProgramError::Invalid {
            origin: origin.to_string(),
            segment,
            key,
            message,
        };
        if dof == 0 || dof > MAX_JOINTS {
            return Err(bad(
                0,
                "program.dof",
                format!("must be 1..={MAX_JOINTS}, got {dof}"),
            ));
        }
        let vector = |segment: usize, key: &'static str, v: &Values, scale: f64| {
            let mut out = JointVector::zeros();
            match v {
                Values::One(x) => out.rows_mut(0, dof).fill(x * scale),
                Values::Many(xs) if xs.len() == dof => {
                    for (i, x) in xs.iter().enumerate() {
                        out[i] = x * scale;
                    }
                }
                Values::Many(xs) => {
                    return Err(bad(
                        segment,
                        key,
                        format!("needs {dof} values, got {}", xs.len()),
                    ));
                }
            }
            if let Some(i) = (0..dof).find(|&i| !out[i].is_finite()) {
                return Err(bad(segment, key, format!("value {i} is not finite")));
            }
            Ok(out)
        };
        if let Some(k) = kinds
            && k.len() != dof
        {
            return Err(bad(
                0,
                "program.dof",
                format!("is {dof} but the robot has {} joints", k.len()),
            ));
        }
        let deg = DEG;
        // Keys in degrees (limits, cruise velocity) are for revolute joints only.
        let angles_only = |segment: usize, key: &'static str| match kinds
            .and_then(|k| k.iter().position(|k| *k == JointKind::Prismatic))
        {
            Some(i) => Err(bad(
                segment,
                key,
                format!(
                    "joint {} is prismatic but this key is in degrees (a program has no length form of it yet: leave it out to use the robot's limits)",
                    i + 1
                ),
            )),
            None => Ok(()),
        };
        if file.limits.is_some() {
            angles_only(0, "limits")?;
        }
        let limits = match &file.limits {
            None => None,
            Some(l) => {
                let v = [
                    vector(0, "limits.vel_deg_s", &l.vel_deg_s, deg)?,
                    vector(0, "limits.acc_deg_s2", &l.acc_deg_s2, deg)?,
                    vector(0, "limits.jerk_deg_s3", &l.jerk_deg_s3, deg)?,
                ];
                for (k, key) in [
                    "limits.vel_deg_s",
                    "limits.acc_deg_s2",
                    "limits.jerk_deg_s3",
                ]
                .into_iter()
                .enumerate()
                {
                    if let Some(i) = (0..dof).find(|&i| v[k][i] <= 0.0) {
                        return Err(bad(0, key, format!("value {i} must be > 0")));
                    }
                }
                Some(v)
            }
        };
        if file.segment.is_empty() {
            return Err(bad(
                0,
                "segment",
                "a program needs at least one segment".into(),
            ));
        }
        let mut segments = Vec::with_capacity(file.segment.len());
        for (k, s) in file.segment.iter().enumerate() {
            let joint = |key: &'static str, xs: &Vec<f64>, scale: f64| {
                vector(k, key, &Values::Many(xs.clone()), scale)
            };
            let given = [&s.q_deg, &s.q_rad, &s.q_mm, &s.q_m, &s.q_deg_mm, &s.q_rad_m];
            let joint_keys: Vec<(TargetKey, &Vec<f64>)> = TARGET_KEYS
                .into_iter()
                .zip(given)
                .filter_map(|(k, v)| v.as_ref().map(|v| (k, v)))
                .collect();
            let target = match (joint_keys.as_slice(), &s.pose) {
                ([((key, rev, pri), q)], None) => {
                    let mut out = joint(key, q, 1.0)?;
                    for i in 0..dof {
                        let kind = match kinds {
                            Some(k) => k[i],
                            None if rev.is_some() => JointKind::Revolute,
                            None => JointKind::Prismatic,
                        };
                        let scale = match kind {
                            JointKind::Revolute => *rev,
                            JointKind::Prismatic => *pri,
                        };
                        let Some(scale) = scale else {
                            let (is, fits) = match kind {
                                JointKind::Revolute => {
                                    ("revolute", "an angle: q_deg, q_rad, or q_deg_mm")
                                }
                                JointKind::Prismatic => {
                                    ("prismatic", "a length: q_mm, q_m, or q_deg_mm")
                                }
                            };
                            return Err(bad(
                                k,
                                key,
                                format!(
                                    "joint {} is {is}: its target is {fits} (each joint in its type's unit)",
                                    i + 1
                                ),
                            ));
                        };
                        if kinds.is_none() && rev.is_some() && pri.is_some() && rev != pri {
                            return Err(bad(
                                k,
                                key,
                                "needs the robot's joint types: load with Program::from_toml_str_for"
                                    .into(),
                            ));
                        }
                        out[i] *= scale;
                    }
                    Target::Joint(out)
                }
                ([], Some(p)) => {
                    if p.xyz_mm.iter().chain(&p.rpy_deg).any(|x| !x.is_finite()) {
                        return Err(bad(k, "pose", "values must be finite".into()));
                    }
                    Target::Cartesian(CartesianPose {
                        xyz_m: p.xyz_mm.map(|x| x * 1e-3),
                        rpy_rad: p.rpy_deg.map(|x| x * deg),
                    })
                }
                _ => {
                    return Err(bad(
                        k,
                        "q_deg",
                        "give exactly one of q_deg, q_rad, q_mm, q_m, q_deg_mm, q_rad_m, pose"
                            .into(),
                    ));
                }
            };
            let profile = s.profile.unwrap_or(ProfileKind::Soft);
            if let Some(t) = s.duration_s
                && !(t.is_finite() && t > 0.0)
            {
                return Err(bad(k, "duration_s", format!("must be > 0, got {t}")));
            }
            if profile != ProfileKind::Soft && s.duration_s.is_none() {
                return Err(bad(
                    k,
                    "duration_s",
                    "required for cubic, quintic and lspb".into(),
                ));
            }
            let cruise_velocity = match (&s.cruise_vel_deg_s, profile) {
                (None, _) => None,
                (Some(v), ProfileKind::Lspb) => {
                    angles_only(k, "cruise_vel_deg_s")?;
                    Some(vector(k, "cruise_vel_deg_s", v, deg)?)
                }
                (Some(_), _) => return Err(bad(k, "cruise_vel_deg_s", "only for lspb".into())),
            };
            let end = match s.end.unwrap_or(EndToml::Stop) {
                EndToml::Stop => {
                    if s.blend_s.is_some() {
                        return Err(bad(k, "blend_s", "only with end = \"blend\"".into()));
                    }
                    End::Stop
                }
                EndToml::Blend => {
                    if profile == ProfileKind::Lspb {
                        return Err(bad(k, "end", "lspb segments stop at their target".into()));
                    }
                    if let Some(b) = s.blend_s
                        && !(b.is_finite() && b >= 0.0)
                    {
                        return Err(bad(k, "blend_s", format!("must be >= 0, got {b}")));
                    }
                    End::Blend { blend: s.blend_s }
                }
            };
            segments.push(Segment {
                name: s.name.clone(),
                target,
                profile,
                duration: s.duration_s,
                cruise_velocity,
                end,
            });
        }
        Ok(Program {
            name: file.program.name,
            dof,
            limits,
            segments,
        })
    }

    /// Plans every segment, the first from `start`, each next one from the state
    /// where its predecessor hands over. `limits` are the robot's (the program's
    /// `[limits]` table, if any, replaces velocity, acceleration and jerk).
    ///
    /// Blending: a cubic or quintic segment followed by a cubic or quintic segment
    /// passes its target with the classic via velocity (mean of the two neighbouring
    /// slopes when they agree in sign, else 0; within vmax) and zero acceleration. A
    /// soft-motion segment hands over `blend_s` (default a quarter of its duration)
    /// before its end, and the next segment starts from that moving state.
    pub fn plan_all(
        &self,
        start: &MotionState,
        limits: &KinematicLimits,
        solver: &dyn CartesianSolver,
    ) -> Result<Vec<PlannedSegment>, ProgramError> {
        let dof = self.dof;
        let mut lim = *limits;
        if let Some([v, a, j]) = self.limits {
            lim.velocity = v;
            lim.acceleration = a;
            lim.jerk = j;
        }
        // Resolve all targets first (each IK seeded with the previous target).
        let mut targets = Vec::with_capacity(self.segments.len());
        let mut seed = start.q;
        for (k, s) in self.segments.iter().enumerate() {
            let q = match &s.target {
                Target::Joint(q) => *q,
                Target::Cartesian(p) => {
                    solver.solve(p, &seed).map_err(|message| ProgramError::Ik {
                        origin: self.name.clone(),
                        segment: k,
                        message,
                    })?
                }
            };
            targets.push(q);
            seed = q;
        }
        let mut out = Vec::with_capacity(self.segments.len());
        let mut state = *start;
        for (k, s) in self.segments.iter().enumerate() {
            let next = self.segments.get(k + 1);
            let mut target = MotionState::at_rest(targets[k]);
            let poly = |p: ProfileKind| matches!(p, ProfileKind::Cubic | ProfileKind::Quintic);
            if let (End::Blend { .. }, Some(n)) = (s.end, next)
                && poly(s.profile)
                && poly(n.profile)
            {
                let prev = if k == 0 { start.q } else { targets[k - 1] };
                let (t0, t1) = (s.duration.unwrap_or(1.0), n.duration.unwrap_or(1.0));
                for i in 0..dof {
                    let (m0, m1) = (
                        (targets[k][i] - prev[i]) / t0,
                        (targets[k + 1][i] - targets[k][i]) / t1,
                    );
                    let v = if m0 * m1 > 0.0 { 0.5 * (m0 + m1) } else { 0.0 };
                    target.qd[i] = v.clamp(-lim.velocity[i], lim.velocity[i]);
                }
            }
            let profile = match s.profile {
                ProfileKind::Cubic => Profile::Cubic {
                    duration: s.duration.unwrap_or(0.0),
                },
                ProfileKind::Quintic => Profile::Quintic {
                    duration: s.duration.unwrap_or(0.0),
                },
                ProfileKind::Lspb => Profile::Lspb {
                    duration: s.duration.unwrap_or(0.0),
                    cruise_velocity: s.cruise_velocity,
                },
                ProfileKind::Soft => Profile::Soft {
                    min_duration: s.duration,
                },
            };
            let req = MotionRequest {
                dof,
                start: state,
                target,
                profile,
                limits: lim,
            };
            let trajectory = Trajectory::plan(&req).map_err(|source| ProgramError::Plan {
                origin: self.name.clone(),
                segment: k,
                source,
            })?;
            let d = trajectory.duration();
            let hand_over = match (s.end, s.profile, next) {
                (End::Blend { blend }, ProfileKind::Soft, Some(_)) => {
                    (d - blend.unwrap_or(0.25 * d)).max(0.0)
                }
                _ => d,
            };
            state = if hand_over >= d {
                let end = trajectory.sample(d);
                MotionState {
                    q: end.q,
                    qd: end.qd,
                    qdd: end.qdd,
                }
            } else {
                trajectory.sample(hand_over).state()
            };
            // Cubic ends may carry an acceleration a next cubic/LSPB cannot take.
            if let Some(n) = next
                && matches!(n.profile, ProfileKind::Cubic | ProfileKind::Lspb)
            {
                state.qdd = JointVector::zeros();
            }
            out.push(PlannedSegment {
                trajectory,
                hand_over,
            });
        }
        Ok(out)
    }
}

/// Steps a planned program per cycle, switching segments at their hand-over times.
/// Nothing here allocates after construction.
#[derive(Debug, Clone)]
pub struct ProgramRunner {
    segments: Vec<PlannedSegment>,
    index: usize,
    generator: Generator,
}

impl ProgramRunner {
    /// Starts at the first segment; `None` for an empty plan.
    pub fn new(segments: Vec<PlannedSegment>) -> Option<Self> {
        let first = segments.first()?.trajectory;
        Some(Self {
            segments,
            index: 0,
            generator: Generator::new(first),
        })
    }

    /// Advances by `dt` seconds; `Finished` once the last segment has ended.
    pub fn update(&mut self, dt: f64) -> (Status, Sample) {
        let mut s = Sample::default();
        let status = self.update_into(dt, &mut s);
        (status, s)
    }

    /// [`ProgramRunner::update`] written into `out` (every lane): the per-cycle form
    /// (see [`crate::Generator::update_into`]).
    pub fn update_into(&mut self, dt: f64, out: &mut Sample) -> Status {
        let mut t = self.generator.time() + dt;
        while self.index + 1 < self.segments.len() && t >= self.segments[self.index].hand_over {
            t -= self.segments[self.index].hand_over;
            self.index += 1;
            self.generator.replace(self.segments[self.index].trajectory);
        }
        self.generator.at_into(t, out)
    }

    /// Index of the running segment.
    pub fn segment(&self) -> usize {
        self.index
    }

    /// Total program time until the last segment ends.
    pub fn duration(&self) -> f64 {
        let n = self.segments.len();
        self.segments[..n.saturating_sub(1)]
            .iter()
            .map(|s| s.hand_over)
            .sum::<f64>()
            + self
                .segments
                .last()
                .map_or(0.0, |s| s.trajectory.duration())
    }
}
