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
use microrobot_keypath::{KeyError, Problem, Table as KeyTable, join};
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
        reader.robot(&KeyTable::root(origin, &table))
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
        let none = Table::new();
        let joints = KeyTable::root(origin, &none).opt_table("joints")?;
        reader.assemble_urdf(chain, &joints, Pose::IDENTITY, None, None)
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
        let root = KeyTable::root(&origin, &table);
        if is_overlay(&table) {
            let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
            reader.overlay(&root, &dir)
        } else {
            reader.robot(&root)
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

impl From<KeyError> for RobotFileError {
    fn from(e: KeyError) -> Self {
        let KeyError { file, key, problem } = e;
        match problem {
            Problem::Missing => Self::MissingKey { file, key },
            Problem::Unknown { expected } => Self::UnknownKey {
                file,
                key,
                expected,
            },
            Problem::WrongType { expected } => Self::WrongType {
                file,
                key,
                expected,
            },
            Problem::NonFinite(value) => Self::NonFinite { file, key, value },
            Problem::Invalid(message) => Self::Invalid { file, key, message },
        }
    }
}

/// Reads a robot file's tables (the key-by-key readers of [`microrobot_keypath`]) into a
/// [`Robot`], with the checks that span keys.
struct Reader<'a> {
    file: &'a str,
}

type Res<T> = Result<T, RobotFileError>;

/// A positive number at `key`.
fn positive(t: &KeyTable<'_>, key: &str) -> Res<f64> {
    let x = t.number(key)?;
    if x <= 0.0 {
        return Err(t.invalid(key, format!("{x} must be > 0")).into());
    }
    Ok(x)
}

/// A number >= 0 at `key`; `default` when absent (`None`: required).
fn non_negative(t: &KeyTable<'_>, key: &str, default: Option<f64>) -> Res<f64> {
    let x = match default {
        Some(d) => t.opt_number(key)?.unwrap_or(d),
        None => t.number(key)?,
    };
    if x < 0.0 {
        return Err(t
            .invalid(key, format!("{x} is negative, must be >= 0"))
            .into());
    }
    Ok(x)
}

/// Three finite numbers at `key`.
fn vec3(t: &KeyTable<'_>, key: &str) -> Res<Vector3<f64>> {
    let arr = match t.get(key) {
        None => return Err(t.error(key, Problem::Missing).into()),
        Some(Value::Array(a)) if a.len() == 3 => a,
        Some(_) => return Err(t.wrong_type(key, "an array of 3 numbers").into()),
    };
    let mut v = Vector3::zeros();
    for (i, x) in arr.iter().enumerate() {
        v[i] = t.number_of(x, format!("{}[{i}]", t.key(key)))?;
    }
    Ok(v)
}

/// A 3×3 array of finite numbers at `key`.
fn mat3(t: &KeyTable<'_>, key: &str) -> Res<Matrix3<f64>> {
    let full = t.key(key);
    let rows = match t.get(key) {
        None => return Err(t.error(key, Problem::Missing).into()),
        Some(Value::Array(a)) if a.len() == 3 => a,
        Some(_) => return Err(t.wrong_type(key, "a 3×3 array of arrays").into()),
    };
    let mut m = Matrix3::zeros();
    for (r, row) in rows.iter().enumerate() {
        let row = match row {
            Value::Array(a) if a.len() == 3 => a,
            _ => {
                return Err(RobotFileError::WrongType {
                    file: t.file().to_string(),
                    key: format!("{full}[{r}]"),
                    expected: "an array of 3 numbers",
                });
            }
        };
        for (c, x) in row.iter().enumerate() {
            m[(r, c)] = t.number_of(x, format!("{full}[{r}][{c}]"))?;
        }
    }
    Ok(m)
}

impl Reader<'_> {
    fn invalid(&self, key: String, message: String) -> RobotFileError {
        RobotFileError::Invalid {
            file: self.file.to_string(),
            key,
            message,
        }
    }

    fn robot(&self, root: &KeyTable<'_>) -> Res<Robot> {
        root.allow(&["robot", "joints", "tool", "payload"])?;
        let head = root.table("robot")?;
        head.allow(&["name", "gravity_mps2"])?;
        let name = head.string("name")?;
        if name.trim().is_empty() {
            return Err(self.invalid("robot.name".into(), "must not be empty".into()));
        }
        let gravity = vec3(&head, "gravity_mps2")?;

        let joint_values = match root.get("joints") {
            None => return Err(root.error("joints", Problem::Missing).into()),
            Some(Value::Array(a)) => a,
            Some(_) => {
                return Err(root
                    .wrong_type("joints", "an array of tables ([[joints]])")
                    .into());
            }
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
                return Err(RobotFileError::WrongType {
                    file: self.file.to_string(),
                    key: path,
                    expected: "a table",
                });
            };
            let joint = self.joint(&root.element(path.clone(), t))?;
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

    /// `[tool]` (`xyz_mm`, `rpy_deg`) and `[payload]` of a DH file or an overlay.
    fn tool_and_payload(&self, root: &KeyTable<'_>) -> Res<(Pose, Option<LinkInertia>)> {
        let t = root.section("tool", &["xyz_mm", "rpy_deg"])?;
        let tool = match t.raw() {
            None => Pose::IDENTITY,
            Some(_) => Pose::from_xyz_rpy(vec3(&t, "xyz_mm")? * MM, vec3(&t, "rpy_deg")? * DEG),
        };
        let t = root.section("payload", &["mass_kg", "com_mm", "inertia_kgmm2"])?;
        let payload = match t.raw() {
            None => None,
            Some(_) => Some(self.inertia(&t)?),
        };
        Ok((tool, payload))
    }

    /// An overlay: `[robot]` `urdf` (relative to the overlay), optional
    /// `name`, `base_link`, `tip_link`, `gravity_mps2`; `[joints.NAME]` limits,
    /// actuator and friction values in the DH files' units; `[lock]` positions
    /// (rad or m, as in URDF) of joints off the path; `[tool]`, `[payload]`.
    fn overlay(&self, root: &KeyTable<'_>, dir: &Path) -> Res<Robot> {
        root.allow(&["robot", "joints", "lock", "tool", "payload"])?;
        let head = root.table("robot")?;
        head.allow(&["urdf", "name", "base_link", "tip_link", "gravity_mps2"])?;
        let urdf_rel = head.string("urdf")?;
        let base_link = head.opt_string("base_link")?;
        let tip_link = head.opt_string("tip_link")?;
        let name = head.opt_string("name")?;
        if name.is_some_and(|n| n.trim().is_empty()) {
            return Err(self.invalid("robot.name".into(), "must not be empty".into()));
        }
        let gravity = match head.get("gravity_mps2") {
            None => None,
            Some(_) => Some(vec3(&head, "gravity_mps2")?),
        };
        let mut lock = Vec::new();
        let t = root.opt_table("lock")?;
        for (k, v) in t.raw().into_iter().flatten() {
            lock.push((k.clone(), t.number_of(v, t.key(k))?));
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
        let joints_t = root.opt_table("joints")?;
        let (tool, payload) = self.tool_and_payload(root)?;
        self.assemble_urdf(chain, &joints_t, tool, payload, gravity)
    }

    /// The robot from a URDF chain and the overlay's `[joints]` table (empty for
    /// a bare URDF); limits still missing are listed by their overlay keys.
    fn assemble_urdf(
        &self,
        mut chain: urdf::UrdfChain,
        joints_t: &KeyTable<'_>,
        tool: Pose,
        payload: Option<LinkInertia>,
        gravity: Option<Vector3<f64>>,
    ) -> Res<Robot> {
        let names: Vec<&str> = chain.joints.iter().map(|j| j.name.as_str()).collect();
        for k in joints_t.raw().into_iter().flat_map(|t| t.keys()) {
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
            let t = joints_t.section(&joint.name, &keys)?;
            let path = t.path().to_string();
            if t.raw().is_some() {
                let l = &mut joint.limits;
                for (k, slot, scale) in [
                    (keys[0], &mut l.velocity, unit),
                    (keys[1], &mut l.acceleration, unit),
                    (keys[2], &mut l.jerk, unit),
                    (keys[3], &mut l.effort, 1.0),
                ] {
                    if t.get(k).is_some() {
                        *slot = positive(&t, k)? * scale;
                    }
                }
                let rotor_scale = if revolute { KGMM2 } else { 1.0 };
                joint.rotor_inertia = non_negative(&t, keys[4], Some(0.0))? * rotor_scale;
                if t.get(keys[5]).is_some() {
                    joint.gear_ratio = positive(&t, keys[5])?;
                }
                let (v, c) = (joint.viscous_friction, joint.coulomb_friction);
                joint.viscous_friction = non_negative(&t, keys[6], Some(v))?;
                joint.coulomb_friction = non_negative(&t, keys[7], Some(c))?;
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

    fn joint(&self, t: &KeyTable<'_>) -> Res<Joint> {
        let path = t.path();
        let kind_str = t.string("kind")?;
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
        t.allow(&[
            "name",
            "kind",
            "dh",
            "limits",
            "link",
            "gear_ratio",
            viscous_key,
            coulomb_key,
        ])?;
        let name = t.string("name")?.to_string();
        if name.trim().is_empty() {
            return Err(self.invalid(join(path, "name"), "must not be empty".into()));
        }

        let dh_t = t.table("dh")?;
        dh_t.allow(&["theta_deg", "d_mm", "a_mm", "alpha_deg"])?;
        let dh = DhParameters {
            theta: dh_t.number("theta_deg")? * DEG,
            d: dh_t.number("d_mm")? * MM,
            a: dh_t.number("a_mm")? * MM,
            alpha: dh_t.number("alpha_deg")? * DEG,
        };

        let lim_t = t.table("limits")?;
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
        lim_t.allow(&keys)?;
        let unit = if revolute { DEG } else { MM };
        let min_raw = lim_t.number(keys[0])?;
        let max_raw = lim_t.number(keys[1])?;
        if min_raw > max_raw {
            return Err(lim_t
                .invalid(
                    keys[0],
                    format!("{min_raw} is above {} = {max_raw}", keys[1]),
                )
                .into());
        }
        let limits = JointLimits {
            min: min_raw * unit,
            max: max_raw * unit,
            velocity: positive(&lim_t, keys[2])? * unit,
            acceleration: positive(&lim_t, keys[3])? * unit,
            jerk: positive(&lim_t, keys[4])? * unit,
            effort: positive(&lim_t, keys[5])?,
        };

        let link_t = t.table("link")?;
        let rotor_key = if revolute {
            "rotor_inertia_kgmm2"
        } else {
            "rotor_mass_kg"
        };
        link_t.allow(&["mass_kg", "com_mm", "inertia_kgmm2", rotor_key])?;
        let link = self.inertia(&link_t)?;
        let rotor_inertia =
            non_negative(&link_t, rotor_key, Some(0.0))? * if revolute { KGMM2 } else { 1.0 };

        let gear_ratio = t.opt_number("gear_ratio")?.unwrap_or(1.0);
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
            viscous_friction: non_negative(t, viscous_key, Some(0.0))?,
            coulomb_friction: non_negative(t, coulomb_key, Some(0.0))?,
        })
    }

    /// `mass_kg`, `com_mm`, `inertia_kgmm2` of a link or the payload.
    fn inertia(&self, t: &KeyTable<'_>) -> Res<LinkInertia> {
        let mass = non_negative(t, "mass_kg", None)?;
        let com = vec3(t, "com_mm")? * MM;
        let raw = mat3(t, "inertia_kgmm2")?;
        let key = t.key("inertia_kgmm2");
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
