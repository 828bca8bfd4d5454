//! The immutable robot model: joints placed by DH rows or by general placements
//! (URDF-style), limits, link inertia, actuator and friction data, the tool frame
//! and payload, plus the compact per-joint constants that the hot-path algorithms
//! read.

use crate::MAX_JOINTS;
use crate::math::Pose;
use nalgebra::{Matrix3, Vector3};

/// Joint type: the joint variable `q` is added to DH `theta` (revolute, rad) or
/// to DH `d` (prismatic, m); for a placed joint ([`JointPlacement`]) it is the
/// angle about (rad) or the distance along (m) the joint axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about `z_{i-1}` (DH) or the joint axis.
    Revolute,
    /// Translation along `z_{i-1}` (DH) or the joint axis.
    Prismatic,
}

/// General joint geometry (URDF `<joint>`): frame `i` = frame `i-1` · `origin` ·
/// motion, the motion being a rotation by `q` about `axis` (revolute) or a
/// translation by `q · axis` (prismatic), `axis` a unit vector in the frame that
/// `origin` places. Frame `i` is the joint's child link frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointPlacement {
    /// Constant placement of the joint frame in the parent frame (frame `i-1`).
    pub origin: Pose,
    /// Unit joint axis in the joint frame.
    pub axis: Vector3<f64>,
}

/// Constant part of a standard DH row, SI (rad, m): `T = Rz(theta) Tz(d) Tx(a) Rx(alpha)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhParameters {
    /// Constant offset added to a revolute joint's angle (rad).
    pub theta: f64,
    /// Offset along `z_{i-1}` (m); a prismatic joint's variable adds to it.
    pub d: f64,
    /// Link length along `x_i` (m).
    pub a: f64,
    /// Link twist about `x_i` (rad).
    pub alpha: f64,
}

/// Joint limits in SI: rad (or m), rad/s, rad/s², rad/s³, N·m (or N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// Lower position limit.
    pub min: f64,
    /// Upper position limit.
    pub max: f64,
    /// Largest speed magnitude.
    pub velocity: f64,
    /// Largest acceleration magnitude.
    pub acceleration: f64,
    /// Largest jerk magnitude.
    pub jerk: f64,
    /// Largest joint torque (revolute, N·m) or force (prismatic, N) magnitude.
    pub effort: f64,
}

impl JointLimits {
    /// `q` clamped into `[min, max]`.
    pub fn clamp(&self, q: f64) -> f64 {
        q.max(self.min).min(self.max)
    }

    /// Whether `min <= q <= max`.
    pub fn contains(&self, q: f64) -> bool {
        q >= self.min && q <= self.max
    }
}

/// Rigid-body inertia of one link (or the payload): mass (kg), centre of mass
/// (m) and inertia tensor about the centre of mass (kg·m²), both in the link's
/// own frame `i` (DH: the frame at the end of link `i`; placed joints: the joint's
/// child link frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkInertia {
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in frame `i`, m.
    pub com: Vector3<f64>,
    /// Inertia about the centre of mass, axes of frame `i`, kg·m².
    pub inertia: Matrix3<f64>,
}

impl LinkInertia {
    /// A body with no mass.
    pub const ZERO: LinkInertia = LinkInertia {
        mass: 0.0,
        com: Vector3::new(0.0, 0.0, 0.0),
        inertia: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// The same body seen from a frame in which this body's frame has pose `pose`.
    pub fn transformed(&self, pose: &Pose) -> LinkInertia {
        LinkInertia {
            mass: self.mass,
            com: pose.transform_point(&self.com),
            inertia: pose.rotation * self.inertia * pose.rotation.transpose(),
        }
    }

    /// Both bodies rigidly joined (parallel-axis theorem), same frame.
    pub fn combined(&self, other: &LinkInertia) -> LinkInertia {
        let mass = self.mass + other.mass;
        if mass <= 0.0 {
            return LinkInertia {
                mass: 0.0,
                com: Vector3::zeros(),
                inertia: self.inertia + other.inertia,
            };
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shift = |b: &LinkInertia| {
            let d = b.com - com;
            (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * b.mass
        };
        LinkInertia {
            mass,
            com,
            inertia: self.inertia + shift(self) + other.inertia + shift(other),
        }
    }

    /// Mass and inertia multiplied by `factor` (same centre of mass).
    pub fn scaled(&self, factor: f64) -> LinkInertia {
        LinkInertia {
            mass: self.mass * factor,
            com: self.com,
            inertia: self.inertia * factor,
        }
    }
}

/// One joint and the link that follows it.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// Name from the robot file (unique within the robot).
    pub name: String,
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Constant DH parameters (all zero, and unused, for a placed joint).
    pub dh: DhParameters,
    /// General placement instead of the DH row (`None`: the DH row places the
    /// joint). A robot's joints are either all DH or all placed.
    pub placement: Option<JointPlacement>,
    /// Position, rate and effort limits.
    pub limits: JointLimits,
    /// Inertia of link `i` (without payload).
    pub link: LinkInertia,
    /// Actuator (rotor) inertia reflected to the joint side: adds
    /// `rotor_inertia · qdd_i` to joint `i`'s torque (kg·m², or kg for prismatic).
    pub rotor_inertia: f64,
    /// Gear ratio `N`: motor torque = joint torque / N (see [`Joint::motor_torque`]).
    /// Rotor inertia and friction are already given on the joint side, so the
    /// ratio does not enter the joint-space dynamics.
    pub gear_ratio: f64,
    /// Viscous friction on the joint side, N·m·s/rad (or N·s/m).
    pub viscous_friction: f64,
    /// Coulomb friction magnitude on the joint side, N·m (or N).
    pub coulomb_friction: f64,
}

impl Joint {
    /// Motor-side torque for a joint-side torque: `tau / gear_ratio`.
    pub fn motor_torque(&self, joint_torque: f64) -> f64 {
        joint_torque / self.gear_ratio
    }

    /// Friction torque `viscous · qd + coulomb · sign(qd)`, with `sign(0) = 0`
    /// (a joint at rest carries no Coulomb term: static friction is not modelled,
    /// and `tau(q, 0, 0)` equals the gravity torque exactly).
    pub fn friction_torque(&self, qd: f64) -> f64 {
        friction(self.viscous_friction, self.coulomb_friction, qd)
    }
}

/// `viscous · qd + coulomb · sign(qd)` with `sign(0) = 0`; the sign comes from
/// two comparisons, not branches (a joint's direction is unpredictable).
#[inline(always)]
pub(crate) fn friction(viscous: f64, coulomb: f64, qd: f64) -> f64 {
    let sign = f64::from(u8::from(qd > 0.0)) - f64::from(u8::from(qd < 0.0));
    viscous * qd + coulomb * sign
}

/// Why a [`Robot`] cannot be assembled from parts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotError {
    /// The chain must have 1 to [`MAX_JOINTS`] joints.
    #[error("a robot needs 1 to {max} joints, got {got}", max = MAX_JOINTS)]
    JointCount {
        /// Number of joints given.
        got: usize,
    },
    /// Some joints have a DH row and others a placement.
    #[error(
        "joint \"{joint}\" mixes DH rows and placements: a robot's joints are all one or the other"
    )]
    MixedGeometry {
        /// The first joint of the other kind.
        joint: String,
    },
    /// A placed joint's axis is zero or not finite.
    #[error("joint \"{joint}\": the axis must be a finite non-zero vector")]
    BadAxis {
        /// The joint.
        joint: String,
    },
}

/// A named frame rigidly attached to one of the robot's frames (URDF: every
/// link on the base→tip path, including those merged by fixed joints).
#[derive(Clone, Debug, PartialEq)]
pub struct LinkFrame {
    /// Link name.
    pub name: String,
    /// Index of the frame it is attached to (0: the base, `i`: joint `i`'s frame).
    pub frame: usize,
    /// Its pose in that frame.
    pub offset: Pose,
}

/// DH twist `alpha` classified: exactly 0 or ±90° (to 1e-12 rad, where the
/// rotation `Rx(alpha)` is a signed permutation), or anything else.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Twist {
    #[default]
    Zero,
    PlusQuarter,
    MinusQuarter,
    General,
}

impl JointConst {
    /// Constants of a joint with twist `alpha` and nothing else (for tests).
    #[cfg(test)]
    pub fn with_twist(alpha: f64) -> JointConst {
        let twist = Twist::of(alpha);
        JointConst {
            ca: twist.cos(alpha),
            sa: twist.sin(alpha),
            twist,
            ..JointConst::default()
        }
    }
}

impl Twist {
    fn of(alpha: f64) -> Twist {
        let half_pi = std::f64::consts::FRAC_PI_2;
        if alpha.abs() < 1e-12 {
            Twist::Zero
        } else if (alpha - half_pi).abs() < 1e-12 {
            Twist::PlusQuarter
        } else if (alpha + half_pi).abs() < 1e-12 {
            Twist::MinusQuarter
        } else {
            Twist::General
        }
    }
    fn cos(self, alpha: f64) -> f64 {
        match self {
            Twist::Zero => 1.0,
            Twist::PlusQuarter | Twist::MinusQuarter => 0.0,
            Twist::General => alpha.cos(),
        }
    }
    fn sin(self, alpha: f64) -> f64 {
        match self {
            Twist::Zero => 0.0,
            Twist::PlusQuarter => 1.0,
            Twist::MinusQuarter => -1.0,
            Twist::General => alpha.sin(),
        }
    }
}

/// Which components of a constant vector can be non-zero: a cross product with
/// a vector along one axis needs two multiplications instead of six. DH frame
/// offsets and link centres of mass very often lie along one axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Sparsity {
    /// The zero vector.
    #[default]
    Zero,
    /// Only `x` non-zero.
    X,
    /// Only `y` non-zero.
    Y,
    /// Only `z` non-zero.
    Z,
    /// Any vector.
    General,
}

impl Sparsity {
    /// The class of `v` (exact zeros only).
    pub(crate) fn of(v: &Vector3<f64>) -> Sparsity {
        match (v.x != 0.0, v.y != 0.0, v.z != 0.0) {
            (false, false, false) => Sparsity::Zero,
            (true, false, false) => Sparsity::X,
            (false, true, false) => Sparsity::Y,
            (false, false, true) => Sparsity::Z,
            _ => Sparsity::General,
        }
    }
}

/// Per-joint constants in the form the algorithms read (SI).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct JointConst {
    pub revolute: bool,
    pub theta0: f64,
    pub d0: f64,
    pub a: f64,
    pub ca: f64,
    pub sa: f64,
    /// Twist class, so the common 0 and ±90° twists skip multiplications.
    pub twist: Twist,
    /// Whether frame `i`'s origin can differ from frame `i-1`'s (false for a
    /// revolute joint with `a = d = 0`, whose offset terms are skipped).
    pub offset: bool,
    /// Revolute joints: origin `O_i` seen from `O_{i-1}` in frame `i`,
    /// `p* = (a, d sα, d cα)`, and its sparsity (prismatic joints: `General`,
    /// `p*` varies with `d`).
    pub pstar: Vector3<f64>,
    pub pstar_kind: Sparsity,
    pub rotor: f64,
    pub viscous: f64,
    pub coulomb: f64,
}

/// Per-joint constants of a placed joint ([`JointPlacement`]), SI.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlacedConst {
    pub revolute: bool,
    /// Placement rotation and translation (frame `i-1` → joint frame).
    pub rot: Matrix3<f64>,
    pub pos: Vector3<f64>,
    /// Unit axis in the joint frame (= in frame `i`: the motion keeps it).
    pub axis: Vector3<f64>,
    /// `axis axisᵀ`, for Rodrigues' formula.
    pub axis_outer: Matrix3<f64>,
    /// `R_placement · axis`: a prismatic joint's direction in frame `i-1`.
    pub rot_axis: Vector3<f64>,
    pub rotor: f64,
    pub viscous: f64,
    pub coulomb: f64,
}

impl Default for PlacedConst {
    fn default() -> Self {
        let z = Vector3::z();
        PlacedConst {
            revolute: true,
            rot: Matrix3::identity(),
            pos: Vector3::zeros(),
            axis: z,
            axis_outer: z * z.transpose(),
            rot_axis: z,
            rotor: 0.0,
            viscous: 0.0,
            coulomb: 0.0,
        }
    }
}

/// Body `i` (link plus, for the last one, the payload) in frame `i`, in the forms
/// the algorithms need: about the centre of mass and about the frame origin.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Body {
    pub mass: f64,
    pub com: Vector3<f64>,
    /// Inertia about the centre of mass.
    pub inertia_com: Matrix3<f64>,
    /// First moment of mass `m · c`.
    pub h: Vector3<f64>,
    /// Inertia about the frame origin.
    pub inertia_origin: Matrix3<f64>,
    /// Sparsity of `h` (`Zero`: the centre of mass is at the frame origin).
    pub h_kind: Sparsity,
    /// Diagonal of `inertia_origin`.
    pub inertia_diag: Vector3<f64>,
    /// `inertia_origin` has no products of inertia: `inertia_diag` is all of it.
    pub diagonal: bool,
}

impl Default for Body {
    fn default() -> Self {
        Body::from_link(&LinkInertia::ZERO)
    }
}

impl Body {
    fn from_link(l: &LinkInertia) -> Body {
        let c = l.com;
        let inertia_origin =
            l.inertia + (Matrix3::identity() * c.norm_squared() - c * c.transpose()) * l.mass;
        Body {
            mass: l.mass,
            com: c,
            inertia_com: l.inertia,
            h: c * l.mass,
            inertia_origin,
            h_kind: Sparsity::of(&(c * l.mass)),
            inertia_diag: inertia_origin.diagonal(),
            diagonal: inertia_origin == Matrix3::from_diagonal(&inertia_origin.diagonal()),
        }
    }
}

/// An immutable serial-arm model in SI units. Cheap to share (`&Robot`) between
/// threads; per-caller scratch lives in [`crate::ModelData`].
#[derive(Clone, Debug)]
pub struct Robot {
    name: String,
    gravity: Vector3<f64>,
    joints: Vec<Joint>,
    tool: Pose,
    payload: Option<LinkInertia>,
    pub(crate) dof: usize,
    pub(crate) tool_is_identity: bool,
    /// Every joint revolute, every body's inertia about its frame origin diagonal,
    /// no friction: the hot paths are compiled for this shape without the branches
    /// for the other cases (see `isa::for_shape`).
    pub(crate) plain: bool,
    pub(crate) consts: [JointConst; MAX_JOINTS],
    pub(crate) bodies: [Body; MAX_JOINTS],
    /// The joints are placed ([`JointPlacement`]), not DH rows: the algorithms
    /// take the general path (`crate::general`) with `placed`.
    pub(crate) general: bool,
    pub(crate) placed: [PlacedConst; MAX_JOINTS],
    links: Vec<LinkFrame>,
    missing_limits: Vec<String>,
    warnings: Vec<String>,
}

impl Robot {
    /// Assembles a robot from already validated parts (the file loader checks
    /// every value; this constructor only refuses a chain that does not fit,
    /// mixes DH rows with placements, or has a zero or non-finite axis).
    /// `tool` is the fixed transform from the last joint frame to the tool frame;
    /// `payload` is given in the tool frame and is added to the last link.
    pub fn new(
        name: impl Into<String>,
        gravity: Vector3<f64>,
        joints: Vec<Joint>,
        tool: Pose,
        payload: Option<LinkInertia>,
    ) -> Result<Robot, RobotError> {
        let dof = joints.len();
        if dof == 0 || dof > MAX_JOINTS {
            return Err(RobotError::JointCount { got: dof });
        }
        let general = joints[0].placement.is_some();
        if let Some(j) = joints.iter().find(|j| j.placement.is_some() != general) {
            return Err(RobotError::MixedGeometry {
                joint: j.name.clone(),
            });
        }
        let mut consts = [JointConst::default(); MAX_JOINTS];
        let mut bodies = [Body::default(); MAX_JOINTS];
        let mut placed = [PlacedConst::default(); MAX_JOINTS];
        for (i, j) in joints.iter().enumerate() {
            if let Some(p) = &j.placement {
                let norm = p.axis.norm();
                if !(norm.is_finite() && norm > 0.0) {
                    return Err(RobotError::BadAxis {
                        joint: j.name.clone(),
                    });
                }
                let axis = p.axis / norm;
                placed[i] = PlacedConst {
                    revolute: j.kind == JointKind::Revolute,
                    rot: p.origin.rotation,
                    pos: p.origin.translation,
                    axis,
                    axis_outer: axis * axis.transpose(),
                    rot_axis: p.origin.rotation * axis,
                    rotor: j.rotor_inertia,
                    viscous: j.viscous_friction,
                    coulomb: j.coulomb_friction,
                };
            }
            let twist = Twist::of(j.dh.alpha);
            let (ca, sa) = (twist.cos(j.dh.alpha), twist.sin(j.dh.alpha));
            let revolute = j.kind == JointKind::Revolute;
            let pstar = Vector3::new(j.dh.a, j.dh.d * sa, j.dh.d * ca);
            consts[i] = JointConst {
                revolute,
                theta0: j.dh.theta,
                d0: j.dh.d,
                a: j.dh.a,
                ca,
                sa,
                twist,
                offset: !(j.kind == JointKind::Revolute && j.dh.a == 0.0 && j.dh.d == 0.0),
                pstar,
                pstar_kind: if revolute {
                    Sparsity::of(&pstar)
                } else {
                    Sparsity::General
                },
                rotor: j.rotor_inertia,
                viscous: j.viscous_friction,
                coulomb: j.coulomb_friction,
            };
            let mut link = j.link;
            if let (true, Some(p)) = (i == dof - 1, &payload) {
                link = link.combined(&p.transformed(&tool));
            }
            bodies[i] = Body::from_link(&link);
        }
        let tool_is_identity = tool == Pose::IDENTITY;
        let plain = !general
            && (0..dof).all(|i| {
                let jc = &consts[i];
                jc.revolute && jc.viscous == 0.0 && jc.coulomb == 0.0 && bodies[i].diagonal
            });
        Ok(Robot {
            name: name.into(),
            gravity,
            joints,
            tool,
            payload,
            dof,
            tool_is_identity,
            plain,
            consts,
            bodies,
            general,
            placed,
            links: Vec::new(),
            missing_limits: Vec::new(),
            warnings: Vec::new(),
        })
    }

    /// Attaches what a robot file adds beyond the chain: named link frames,
    /// the limit keys it lacks, and load warnings.
    pub(crate) fn with_file_info(
        mut self,
        links: Vec<LinkFrame>,
        missing_limits: Vec<String>,
        warnings: Vec<String>,
    ) -> Robot {
        self.links = links;
        self.missing_limits = missing_limits;
        self.warnings = warnings;
        self
    }

    /// Whether the joints are placed ([`JointPlacement`], e.g. from a URDF) rather
    /// than DH rows.
    pub fn is_placed(&self) -> bool {
        self.general
    }

    /// Named link frames (URDF robots: every link on the base→tip path; empty
    /// for DH robots). Pose in the base frame: `data.frame(l.frame) · l.offset`.
    pub fn links(&self) -> &[LinkFrame] {
        &self.links
    }

    /// The robot-file keys of rate limits the file did not give (e.g.
    /// `joints.panda_joint1.acc_deg_s2` for a URDF without an overlay); those
    /// limits are NaN. The model works without them; a motion tool must refuse
    /// the robot and name these keys.
    pub fn missing_limits(&self) -> &[String] {
        &self.missing_limits
    }

    /// Warnings from loading (e.g. an inertia tensor whose principal moments
    /// break the triangle inequality); the robot loaded regardless.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Robot name from the file.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Number of joints (1 to [`MAX_JOINTS`]).
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Joints, base to tip.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// Gravity acceleration vector in the base frame, m/s².
    pub fn gravity(&self) -> Vector3<f64> {
        self.gravity
    }

    /// Fixed transform from the last joint frame to the tool frame.
    pub fn tool(&self) -> &Pose {
        &self.tool
    }

    /// Payload (in the tool frame), if any.
    pub fn payload(&self) -> Option<&LinkInertia> {
        self.payload.as_ref()
    }

    /// Inertia of body `i` as the dynamics sees it: link `i`, plus the payload for
    /// the last link; frame `i`. `None` when `i >= dof`.
    pub fn body_inertia(&self, i: usize) -> Option<LinkInertia> {
        (i < self.dof).then(|| {
            let b = &self.bodies[i];
            LinkInertia {
                mass: b.mass,
                com: b.com,
                inertia: b.inertia_com,
            }
        })
    }

    /// Lower and upper position limits as joint vectors (zeros beyond `dof`).
    pub fn position_limits(&self) -> (crate::JointVector, crate::JointVector) {
        let mut lo = crate::JointVector::zeros();
        let mut hi = crate::JointVector::zeros();
        for (i, j) in self.joints.iter().enumerate() {
            lo[i] = j.limits.min;
            hi[i] = j.limits.max;
        }
        (lo, hi)
    }

    /// A deliberately wrong copy for simulation studies: every link mass and
    /// inertia tensor (and the payload's) multiplied by `factor`; centres of mass,
    /// geometry, rotor inertia and friction unchanged.
    pub fn with_scaled_link_masses(&self, factor: f64) -> Robot {
        let joints = self
            .joints
            .iter()
            .map(|j| Joint {
                link: j.link.scaled(factor),
                ..j.clone()
            })
            .collect();
        let payload = self.payload.map(|p| p.scaled(factor));
        // The joint count is unchanged, so assembling cannot fail; keep the
        // original rather than panic if it ever did.
        Robot::new(self.name.clone(), self.gravity, joints, self.tool, payload)
            .map(|r| {
                r.with_file_info(
                    self.links.clone(),
                    self.missing_limits.clone(),
                    self.warnings.clone(),
                )
            })
            .unwrap_or_else(|_| self.clone())
    }
}
