//! Robot description files: DH robot files (docs/seed-arm.md, "Robot description"),
//! URDF files, and TOML overlays that name a URDF and add what it lacks. TOML
//! text to [`Robot`], every key checked, units converted once (mm → m, deg →
//! rad, kg·mm² → kg·m²). Errors name the file and the full key path (URDF: the
//! element and its joint or link, `joint[panda_joint4].axis`).

mod urdf;
pub mod urdf_writer;

use crate::MAX_JOINTS;
use crate::math::Pose;
use crate::robot::{DhParameters, Joint, JointKind, JointLimits, LinkInertia, Robot};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use std::path::Path;
use std::path::PathBuf;
use toml::{Table, Value};

/// Why a robot file was refused. Every variant names the file (`origin`) and,
/// where it applies, the key path, e.g. `joints[2].limits.min_deg`.
#[derive(Debug, thiserror::Error)]
pub enum RobotFileError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// File name.
        file: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML.
    #[error("{file}: invalid TOML: {message}")]
    Syntax {
        /// File name.
        file: String,
        /// Parser message (with line and column).
        message: String,
    },
    /// Not a URDF document `urdf-rs` can read (XML syntax, a missing required
    /// attribute, a wrong number of values).
    #[error("{file}: invalid URDF: {message}")]
    UrdfSyntax {
        /// File name.
        file: String,
        /// Parser message.
        message: String,
    },
    /// A required key is absent.
    #[error("{file}: {key}: missing required key")]
    MissingKey {
        /// File name.
        file: String,
        /// Key path.
        key: String,
    },
    /// A key that the format does not define (often a typo or a wrong unit suffix).
    #[error("{file}: {key}: unknown key (expected one of: {expected})")]
    UnknownKey {
        /// File name.
        file: String,
        /// Key path.
        key: String,
        /// Keys allowed at that place.
        expected: String,
    },
    /// A value of the wrong TOML type or shape.
    #[error("{file}: {key}: expected {expected}")]
    WrongType {
        /// File name.
        file: String,
        /// Key path.
        key: String,
        /// What was expected.
        expected: &'static str,
    },
    /// NaN or infinity.
    #[error("{file}: {key}: {value} is not a finite number")]
    NonFinite {
        /// File name.
        file: String,
        /// Key path.
        key: String,
        /// The value.
        value: f64,
    },
    /// A value outside its valid range, or inconsistent with another key.
    #[error("{file}: {key}: {message}")]
    Invalid {
        /// File name.
        file: String,
        /// Key path.
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl RobotFileError {
    /// The key path the error is about (`None` for I/O and syntax errors).
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Io { .. } | Self::Syntax { .. } | Self::UrdfSyntax { .. } => None,
            Self::MissingKey { key, .. }
            | Self::UnknownKey { key, .. }
            | Self::WrongType { key, .. }
            | Self::NonFinite { key, .. }
            | Self::Invalid { key, .. } => Some(key),
        }
    }
}

const MM: f64 = 1.0e-3;
const KGMM2: f64 = 1.0e-6;
const DEG: f64 = std::f64::consts::PI / 180.0;

impl Robot {
    /// Parses a DH robot description (the format of docs/seed-arm.md). `origin` is the
    /// file name used in error messages. An overlay (`[robot] urdf = …`) names a file
    /// relative to itself: load it with [`Robot::from_file`].
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Robot, RobotFileError> {
        let table = parse_toml(text, origin)?;
        let reader = Reader { file: origin };
        if is_overlay(&table) {
            return Err(reader.invalid(
                "robot.urdf".into(),
                "an overlay names its URDF relative to itself: load it with Robot::from_file"
                    .into(),
            ));
        }
        reader.robot(&table)
    }

    /// Parses a URDF robot (`origin`: the file name for errors) with the
    /// defaults: the chain from the root link to the child of the last moving
    /// joint, gravity 9.81 m/s² along −z of the base, no rotor inertia, the tool
    /// frame at the tip link. Acceleration and jerk limits are NaN and listed by
    /// [`Robot::missing_limits`].
    pub fn from_urdf_str(text: &str, origin: &str) -> Result<Robot, RobotFileError> {
        let sel = urdf::Selection {
            base_link: None,
            tip_link: None,
            lock: &[],
            overlay: origin,
        };
        let chain = urdf::load(text, origin, &sel)?;
        let reader = Reader { file: origin };
        reader.assemble_urdf(chain, &Table::new(), Pose::IDENTITY, None, None)
    }

    /// Reads a robot file: a `.urdf`, an overlay (a TOML file with
    /// `[robot] urdf = …`), or a DH robot file. Errors name the file by its
    /// file name.
    pub fn from_file(path: &Path) -> Result<Robot, RobotFileError> {
        let (origin, text) = read_text(path)?;
        let is_urdf = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
        if is_urdf {
            return Robot::from_urdf_str(&text, &origin);
        }
        let table = parse_toml(&text, &origin)?;
        let reader = Reader { file: &origin };
        if is_overlay(&table) {
            let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
            reader.overlay(&table, &dir)
        } else {
            reader.robot(&table)
        }
    }
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn read_text(path: &Path) -> Result<(String, String), RobotFileError> {
    let origin = file_name(path);
    let text = std::fs::read_to_string(path).map_err(|source| RobotFileError::Io {
        file: origin.clone(),
        source,
    })?;
    Ok((origin, text))
}

fn parse_toml(text: &str, origin: &str) -> Result<Table, RobotFileError> {
    text.parse()
        .map_err(|e: toml::de::Error| RobotFileError::Syntax {
            file: origin.to_string(),
            message: e.to_string().trim().to_string(),
        })
}

fn is_overlay(table: &Table) -> bool {
    matches!(table.get("robot"), Some(Value::Table(t)) if t.contains_key("urdf"))
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// Walks the TOML tree, carrying the file name for errors.
struct Reader<'a> {
    file: &'a str,
}

type Res<T> = Result<T, RobotFileError>;

impl Reader<'_> {
    fn missing(&self, key: String) -> RobotFileError {
        RobotFileError::MissingKey {
            file: self.file.to_string(),
            key,
        }
    }
    fn wrong(&self, key: String, expected: &'static str) -> RobotFileError {
        RobotFileError::WrongType {
            file: self.file.to_string(),
            key,
            expected,
        }
    }
    fn invalid(&self, key: String, message: String) -> RobotFileError {
        RobotFileError::Invalid {
            file: self.file.to_string(),
            key,
            message,
        }
    }

    fn check_keys(&self, t: &Table, path: &str, allowed: &[&str]) -> Res<()> {
        for k in t.keys() {
            if !allowed.contains(&k.as_str()) {
                return Err(RobotFileError::UnknownKey {
                    file: self.file.to_string(),
                    key: join(path, k),
                    expected: allowed.join(", "),
                });
            }
        }
        Ok(())
    }

    fn table<'t>(&self, t: &'t Table, path: &str, key: &str) -> Res<&'t Table> {
        match t.get(key) {
            None => Err(self.missing(join(path, key))),
            Some(Value::Table(inner)) => Ok(inner),
            Some(_) => Err(self.wrong(join(path, key), "a table")),
        }
    }

    fn opt_table<'t>(&self, t: &'t Table, path: &str, key: &str) -> Res<Option<&'t Table>> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::Table(inner)) => Ok(Some(inner)),
            Some(_) => Err(self.wrong(join(path, key), "a table")),
        }
    }

    fn string<'t>(&self, t: &'t Table, path: &str, key: &str) -> Res<&'t str> {
        match t.get(key) {
            None => Err(self.missing(join(path, key))),
            Some(Value::String(s)) => Ok(s),
            Some(_) => Err(self.wrong(join(path, key), "a string")),
        }
    }

    fn value_number(&self, v: &Value, key: String) -> Res<f64> {
        let x = match v {
            Value::Float(x) => *x,
            Value::Integer(i) => *i as f64,
            _ => return Err(self.wrong(key, "a number")),
        };
        if !x.is_finite() {
            return Err(RobotFileError::NonFinite {
                file: self.file.to_string(),
                key,
                value: x,
            });
        }
        Ok(x)
    }

    fn number(&self, t: &Table, path: &str, key: &str) -> Res<f64> {
        match t.get(key) {
            None => Err(self.missing(join(path, key))),
            Some(v) => self.value_number(v, join(path, key)),
        }
    }

    fn opt_number(&self, t: &Table, path: &str, key: &str, default: f64) -> Res<f64> {
        match t.get(key) {
            None => Ok(default),
            Some(v) => self.value_number(v, join(path, key)),
        }
    }

    fn non_negative(&self, t: &Table, path: &str, key: &str, default: Option<f64>) -> Res<f64> {
        let x = match default {
            Some(d) => self.opt_number(t, path, key, d)?,
            None => self.number(t, path, key)?,
        };
        if x < 0.0 {
            return Err(self.invalid(join(path, key), format!("{x} is negative, must be >= 0")));
        }
        Ok(x)
    }

    fn positive(&self, t: &Table, path: &str, key: &str) -> Res<f64> {
        let x = self.number(t, path, key)?;
        if x <= 0.0 {
            return Err(self.invalid(join(path, key), format!("{x} must be > 0")));
        }
        Ok(x)
    }

    fn vec3(&self, t: &Table, path: &str, key: &str) -> Res<Vector3<f64>> {
        let full = join(path, key);
        let arr = match t.get(key) {
            None => return Err(self.missing(full)),
            Some(Value::Array(a)) if a.len() == 3 => a,
            Some(_) => return Err(self.wrong(full, "an array of 3 numbers")),
        };
        let mut v = Vector3::zeros();
        for (i, x) in arr.iter().enumerate() {
            v[i] = self.value_number(x, format!("{full}[{i}]"))?;
        }
        Ok(v)
    }

    fn mat3(&self, t: &Table, path: &str, key: &str) -> Res<Matrix3<f64>> {
        let full = join(path, key);
        let rows = match t.get(key) {
            None => return Err(self.missing(full)),
            Some(Value::Array(a)) if a.len() == 3 => a,
            Some(_) => return Err(self.wrong(full, "a 3×3 array of arrays")),
        };
        let mut m = Matrix3::zeros();
        for (r, row) in rows.iter().enumerate() {
            let row = match row {
                Value::Array(a) if a.len() == 3 => a,
                _ => return Err(self.wrong(format!("{full}[{r}]"), "an array of 3 numbers")),
            };
            for (c, x) in row.iter().enumerate() {
                m[(r, c)] = self.value_number(x, format!("{full}[{r}][{c}]"))?;
            }
        }
        Ok(m)
    }

    fn robot(&self, root: &Table) -> Res<Robot> {
        self.check_keys(root, "", &["robot", "joints", "tool", "payload"])?;
        let head = self.table(root, "", "robot")?;
        self.check_keys(head, "robot", &["name", "gravity_mps2"])?;
        let name = self.string(head, "robot", "name")?;
        if name.trim().is_empty() {
            return Err(self.invalid("robot.name".into(), "must not be empty".into()));
        }
        let gravity = self.vec3(head, "robot", "gravity_mps2")?;

        let joint_values = match root.get("joints") {
            None => return Err(self.missing("joints".into())),
            Some(Value::Array(a)) => a,
            Some(_) => return Err(self.wrong("joints".into(), "an array of tables ([[joints]])")),
        };
        if joint_values.is_empty() || joint_values.len() > MAX_JOINTS {
            return Err(self.invalid(
                "joints".into(),
                format!(
                    "{} joints given, a robot has 1 to {MAX_JOINTS}",
                    joint_values.len()
                ),
            ));
        }
        let mut joints = Vec::with_capacity(joint_values.len());
        for (i, v) in joint_values.iter().enumerate() {
            let path = format!("joints[{i}]");
            let Value::Table(t) = v else {
                return Err(self.wrong(path, "a table"));
            };
            let joint = self.joint(t, &path)?;
            if joints.iter().any(|j: &Joint| j.name == joint.name) {
                return Err(self.invalid(
                    join(&path, "name"),
                    format!("\"{}\" is used by an earlier joint", joint.name),
                ));
            }
            joints.push(joint);
        }

        let (tool, payload) = self.tool_and_payload(root)?;
        let warnings = joints
            .iter()
            .enumerate()
            .filter_map(|(i, j)| {
                urdf::triangle_warning(&j.link.inertia)
                    .map(|w| format!("{}: joints[{i}].link.inertia_kgmm2: {w}", self.file))
            })
            .collect();
        Robot::new(name, gravity, joints, tool, payload)
            .map(|r| r.with_file_info(Vec::new(), Vec::new(), warnings))
            .map_err(|e| self.invalid("joints".into(), e.to_string()))
    }

    fn opt_string<'t>(&self, t: &'t Table, path: &str, key: &str) -> Res<Option<&'t str>> {
        match t.get(key) {
            None => Ok(None),
            Some(_) => self.string(t, path, key).map(Some),
        }
    }

    /// `[tool]` (`xyz_mm`, `rpy_deg`) and `[payload]` of a DH file or an overlay.
    fn tool_and_payload(&self, root: &Table) -> Res<(Pose, Option<LinkInertia>)> {
        let tool = match self.opt_table(root, "", "tool")? {
            None => Pose::IDENTITY,
            Some(t) => {
                self.check_keys(t, "tool", &["xyz_mm", "rpy_deg"])?;
                let xyz = self.vec3(t, "tool", "xyz_mm")? * MM;
                let rpy = self.vec3(t, "tool", "rpy_deg")? * DEG;
                Pose::from_xyz_rpy(xyz, rpy)
            }
        };
        let payload = match self.opt_table(root, "", "payload")? {
            None => None,
            Some(t) => {
                self.check_keys(t, "payload", &["mass_kg", "com_mm", "inertia_kgmm2"])?;
                Some(self.inertia(t, "payload")?)
            }
        };
        Ok((tool, payload))
    }

    /// An overlay: `[robot]` `urdf` (relative to the overlay), optional
    /// `name`, `base_link`, `tip_link`, `gravity_mps2`; `[joints.NAME]` limits,
    /// actuator and friction values in the DH files' units; `[lock]` positions
    /// (rad or m, as in URDF) of joints off the path; `[tool]`, `[payload]`.
    fn overlay(&self, root: &Table, dir: &Path) -> Res<Robot> {
        self.check_keys(root, "", &["robot", "joints", "lock", "tool", "payload"])?;
        let head = self.table(root, "", "robot")?;
        self.check_keys(
            head,
            "robot",
            &["urdf", "name", "base_link", "tip_link", "gravity_mps2"],
        )?;
        let urdf_rel = self.string(head, "robot", "urdf")?;
        let base_link = self.opt_string(head, "robot", "base_link")?;
        let tip_link = self.opt_string(head, "robot", "tip_link")?;
        let name = self.opt_string(head, "robot", "name")?;
        if name.is_some_and(|n| n.trim().is_empty()) {
            return Err(self.invalid("robot.name".into(), "must not be empty".into()));
        }
        let gravity = match head.get("gravity_mps2") {
            None => None,
            Some(_) => Some(self.vec3(head, "robot", "gravity_mps2")?),
        };
        let mut lock = Vec::new();
        if let Some(t) = self.opt_table(root, "", "lock")? {
            for (k, v) in t {
                lock.push((k.clone(), self.value_number(v, join("lock", k))?));
            }
        }
        let urdf_path: PathBuf = dir.join(urdf_rel);
        let text = std::fs::read_to_string(&urdf_path).map_err(|e| {
            self.invalid(
                "robot.urdf".into(),
                format!("cannot read {}: {e}", urdf_path.display()),
            )
        })?;
        let urdf_name = file_name(&urdf_path);
        let sel = urdf::Selection {
            base_link,
            tip_link,
            lock: &lock,
            overlay: self.file,
        };
        let mut chain = urdf::load(&text, &urdf_name, &sel)?;
        if let Some(n) = name {
            chain.name = n.to_string();
        }
        let joints_t = self
            .opt_table(root, "", "joints")?
            .cloned()
            .unwrap_or_default();
        let (tool, payload) = self.tool_and_payload(root)?;
        self.assemble_urdf(chain, &joints_t, tool, payload, gravity)
    }

    /// The robot from a URDF chain and the overlay's `[joints]` table (empty for
    /// a bare URDF); limits still missing are listed by their overlay keys.
    fn assemble_urdf(
        &self,
        mut chain: urdf::UrdfChain,
        joints_t: &Table,
        tool: Pose,
        payload: Option<LinkInertia>,
        gravity: Option<Vector3<f64>>,
    ) -> Res<Robot> {
        let names: Vec<&str> = chain.joints.iter().map(|j| j.name.as_str()).collect();
        for k in joints_t.keys() {
            if !names.contains(&k.as_str()) {
                return Err(RobotFileError::UnknownKey {
                    file: self.file.to_string(),
                    key: join("joints", k),
                    expected: format!("a moving joint on the path: {}", names.join(", ")),
                });
            }
        }
        let mut missing = Vec::new();
        for joint in &mut chain.joints {
            let path = join("joints", &joint.name);
            let revolute = joint.kind == JointKind::Revolute;
            let keys: [&str; 8] = if revolute {
                [
                    "vel_deg_s",
                    "acc_deg_s2",
                    "jerk_deg_s3",
                    "torque_nm",
                    "rotor_inertia_kgmm2",
                    "gear_ratio",
                    "viscous_friction_nms",
                    "coulomb_friction_nm",
                ]
            } else {
                [
                    "vel_mm_s",
                    "acc_mm_s2",
                    "jerk_mm_s3",
                    "force_n",
                    "rotor_mass_kg",
                    "gear_ratio",
                    "viscous_friction_nsm",
                    "coulomb_friction_n",
                ]
            };
            let unit = if revolute { DEG } else { MM };
            if let Some(t) = self.opt_table(joints_t, "joints", &joint.name)? {
                self.check_keys(t, &path, &keys)?;
                let l = &mut joint.limits;
                for (k, slot, scale) in [
                    (keys[0], &mut l.velocity, unit),
                    (keys[1], &mut l.acceleration, unit),
                    (keys[2], &mut l.jerk, unit),
                    (keys[3], &mut l.effort, 1.0),
                ] {
                    if t.contains_key(k) {
                        *slot = self.positive(t, &path, k)? * scale;
                    }
                }
                let rotor_scale = if revolute { KGMM2 } else { 1.0 };
                joint.rotor_inertia =
                    self.non_negative(t, &path, keys[4], Some(0.0))? * rotor_scale;
                if t.contains_key(keys[5]) {
                    joint.gear_ratio = self.positive(t, &path, keys[5])?;
                }
                let (v, c) = (joint.viscous_friction, joint.coulomb_friction);
                joint.viscous_friction = self.non_negative(t, &path, keys[6], Some(v))?;
                joint.coulomb_friction = self.non_negative(t, &path, keys[7], Some(c))?;
            }
            let l = &joint.limits;
            for (k, v) in keys[..4]
                .iter()
                .zip([l.velocity, l.acceleration, l.jerk, l.effort])
            {
                if v.is_nan() {
                    missing.push(join(&path, k));
                }
            }
        }
        let gravity = gravity.unwrap_or(Vector3::new(0.0, 0.0, -9.81));
        let tool = chain.tip.compose(&tool);
        Robot::new(chain.name, gravity, chain.joints, tool, payload)
            .map(|r| r.with_file_info(chain.links, missing, chain.warnings))
            .map_err(|e| self.invalid("joints".into(), e.to_string()))
    }

    fn joint(&self, t: &Table, path: &str) -> Res<Joint> {
        let kind_str = self.string(t, path, "kind")?;
        let kind = match kind_str {
            "revolute" => JointKind::Revolute,
            "prismatic" => JointKind::Prismatic,
            other => {
                return Err(self.invalid(
                    join(path, "kind"),
                    format!("\"{other}\" is not a joint kind (\"revolute\" or \"prismatic\")"),
                ));
            }
        };
        let revolute = kind == JointKind::Revolute;
        let (viscous_key, coulomb_key) = if revolute {
            ("viscous_friction_nms", "coulomb_friction_nm")
        } else {
            ("viscous_friction_nsm", "coulomb_friction_n")
        };
        self.check_keys(
            t,
            path,
            &[
                "name",
                "kind",
                "dh",
                "limits",
                "link",
                "gear_ratio",
                viscous_key,
                coulomb_key,
            ],
        )?;
        let name = self.string(t, path, "name")?.to_string();
        if name.trim().is_empty() {
            return Err(self.invalid(join(path, "name"), "must not be empty".into()));
        }

        let dh_path = join(path, "dh");
        let dh_t = self.table(t, path, "dh")?;
        self.check_keys(dh_t, &dh_path, &["theta_deg", "d_mm", "a_mm", "alpha_deg"])?;
        let dh = DhParameters {
            theta: self.number(dh_t, &dh_path, "theta_deg")? * DEG,
            d: self.number(dh_t, &dh_path, "d_mm")? * MM,
            a: self.number(dh_t, &dh_path, "a_mm")? * MM,
            alpha: self.number(dh_t, &dh_path, "alpha_deg")? * DEG,
        };

        let lim_path = join(path, "limits");
        let lim_t = self.table(t, path, "limits")?;
        let keys: [&str; 6] = if revolute {
            [
                "min_deg",
                "max_deg",
                "vel_deg_s",
                "acc_deg_s2",
                "jerk_deg_s3",
                "torque_nm",
            ]
        } else {
            [
                "min_mm",
                "max_mm",
                "vel_mm_s",
                "acc_mm_s2",
                "jerk_mm_s3",
                "force_n",
            ]
        };
        self.check_keys(lim_t, &lim_path, &keys)?;
        let unit = if revolute { DEG } else { MM };
        let min_raw = self.number(lim_t, &lim_path, keys[0])?;
        let max_raw = self.number(lim_t, &lim_path, keys[1])?;
        if min_raw > max_raw {
            return Err(self.invalid(
                join(&lim_path, keys[0]),
                format!("{min_raw} is above {} = {max_raw}", keys[1]),
            ));
        }
        let limits = JointLimits {
            min: min_raw * unit,
            max: max_raw * unit,
            velocity: self.positive(lim_t, &lim_path, keys[2])? * unit,
            acceleration: self.positive(lim_t, &lim_path, keys[3])? * unit,
            jerk: self.positive(lim_t, &lim_path, keys[4])? * unit,
            effort: self.positive(lim_t, &lim_path, keys[5])?,
        };

        let link_path = join(path, "link");
        let link_t = self.table(t, path, "link")?;
        let rotor_key = if revolute {
            "rotor_inertia_kgmm2"
        } else {
            "rotor_mass_kg"
        };
        self.check_keys(
            link_t,
            &link_path,
            &["mass_kg", "com_mm", "inertia_kgmm2", rotor_key],
        )?;
        let link = self.inertia(link_t, &link_path)?;
        let rotor_inertia = self.non_negative(link_t, &link_path, rotor_key, Some(0.0))?
            * if revolute { KGMM2 } else { 1.0 };

        let gear_ratio = self.opt_number(t, path, "gear_ratio", 1.0)?;
        if gear_ratio <= 0.0 {
            return Err(self.invalid(
                join(path, "gear_ratio"),
                format!("{gear_ratio} must be > 0"),
            ));
        }
        Ok(Joint {
            name,
            kind,
            dh,
            placement: None,
            limits,
            link,
            rotor_inertia,
            gear_ratio,
            viscous_friction: self.non_negative(t, path, viscous_key, Some(0.0))?,
            coulomb_friction: self.non_negative(t, path, coulomb_key, Some(0.0))?,
        })
    }

    /// `mass_kg`, `com_mm`, `inertia_kgmm2` of a link or the payload.
    fn inertia(&self, t: &Table, path: &str) -> Res<LinkInertia> {
        let mass = self.non_negative(t, path, "mass_kg", None)?;
        let com = self.vec3(t, path, "com_mm")? * MM;
        let raw = self.mat3(t, path, "inertia_kgmm2")?;
        let key = join(path, "inertia_kgmm2");
        let scale = raw.abs().max().max(1e-300);
        for (r, c) in [(0, 1), (0, 2), (1, 2)] {
            if (raw[(r, c)] - raw[(c, r)]).abs() > 1e-9 * scale {
                return Err(self.invalid(
                    key,
                    format!(
                        "not symmetric: [{r}][{c}] = {} but [{c}][{r}] = {}",
                        raw[(r, c)],
                        raw[(c, r)]
                    ),
                ));
            }
        }
        let eig = SymmetricEigen::new(raw).eigenvalues;
        let min_eig = eig.min();
        if min_eig < -1e-9 * scale {
            return Err(self.invalid(
                key,
                format!("not positive semi-definite: eigenvalue {min_eig:e} kg·mm² < 0"),
            ));
        }
        Ok(LinkInertia {
            mass,
            com,
            inertia: raw * KGMM2,
        })
    }
}
