//! Forward kinematics (seed section 2.2, eq. 1), the geometric Jacobian (seed
//! section 2.4) and dexterity measures: manipulability, condition number,
//! smallest singular value, rank.

use crate::data::ModelData;
use crate::isa::{Isa, for_shape, multiversion};
use crate::math::Pose;
use crate::robot::{Robot, Twist};
use crate::{Jacobian, JointVector, MAX_JOINTS};
use nalgebra::{Isometry3, Matrix3, SMatrix, Vector3};

/// Evaluates `cos θ_i`, `sin θ_i` and `d_i` of the `n = dof` joints for `q` into `data`
/// (`plain`: `robot.plain`, every joint revolute).
#[inline(always)]
pub(crate) fn update_joint_values<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    n: usize,
    plain: bool,
) {
    let n = n.min(MAX_JOINTS);
    let mut theta = [0.0; MAX_JOINTS];
    for i in 0..n {
        let jc = &robot.consts[i];
        if plain || jc.revolute {
            theta[i] = jc.theta0 + q[i];
            data.d[i] = jc.d0;
        } else {
            theta[i] = jc.theta0;
            data.d[i] = jc.d0 + q[i];
        }
    }
    // The same angles as last time (bit for bit, same joint count) have their
    // sine and cosine already.
    let same = theta
        .iter()
        .zip(&data.theta)
        .fold(n == data.theta_dof, |same, (a, b)| {
            same & (a.to_bits() == b.to_bits())
        });
    if !same {
        data.theta = theta;
        data.theta_dof = n;
        S::sin_cos_joints(n, &theta, &mut data.sin, &mut data.cos);
    }
}

/// Chains the DH transforms from the joint values already in `data`.
///
/// The running frame is kept in locals (axes `x`, `y`, `z` and origin `o`) and
/// only written to `data`: reading the previous frame back from memory would
/// stall on store-to-load forwarding every joint.
#[inline(always)]
pub(crate) fn update_frames(robot: &Robot, data: &mut ModelData, n: usize) {
    let base = &data.frames[0];
    let mut x: Vector3<f64> = base.rotation.column(0).into_owned();
    let mut y: Vector3<f64> = base.rotation.column(1).into_owned();
    let mut z: Vector3<f64> = base.rotation.column(2).into_owned();
    let mut o = base.translation;
    for i in 0..n.min(MAX_JOINTS) {
        let jc = &robot.consts[i];
        let (c, s, d) = (data.cos[i], data.sin[i], data.d[i]);
        // R_prev · Rz(θ): rotate the first two axes about z.
        let xr = x * c + y * s;
        let yr = y * c - x * s;
        // · Rx(α): rotate the last two axes about the new x.
        let (y2, z2) = match jc.twist {
            Twist::Zero => (yr, z),
            Twist::PlusQuarter => (z, -yr),
            Twist::MinusQuarter => (-z, yr),
            Twist::General => (yr * jc.ca + z * jc.sa, z * jc.ca - yr * jc.sa),
        };
        // origin: o_prev + R_prev (a cθ, a sθ, d) = o_prev + a·x_new + d·z_prev
        // (most DH rows have a = 0 or d = 0)
        if jc.a != 0.0 {
            o += xr * jc.a;
        }
        if d != 0.0 {
            o += z * d;
        }
        x = xr;
        y = y2;
        z = z2;
        data.frames[i + 1] = Pose {
            rotation: Matrix3::from_columns(&[x, y, z]),
            translation: o,
        };
    }
    let last = Pose {
        rotation: Matrix3::from_columns(&[x, y, z]),
        translation: o,
    };
    data.tool = if robot.tool_is_identity {
        last
    } else {
        last.compose(robot.tool())
    };
}

#[inline(always)]
pub(crate) fn update_kinematics_with<S: Isa>(robot: &Robot, data: &mut ModelData, q: &JointVector) {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        update_frames(robot, data, n)
    })
}

multiversion! {
    /// [`update_kinematics`] for DH robots.
    #[inline(always)]
    fn update_kinematics_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) => update_kinematics_with;
}

/// Every frame and the tool frame for `q`, left in `data`.
pub(crate) fn update_kinematics(robot: &Robot, data: &mut ModelData, q: &JointVector) {
    if robot.general {
        crate::general::update_kinematics(robot, data, q)
    } else {
        update_kinematics_dh(robot, data, q)
    }
}

#[inline(always)]
pub(crate) fn forward_kinematics_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> Isometry3<f64> {
    update_kinematics_with::<S>(robot, data, q);
    data.tool.to_isometry()
}

#[inline(always)]
pub(crate) fn jacobian_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> Jacobian {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        update_frames(robot, data, n);
        jacobian_of_frames(robot, data, n, plain)
    })
}

#[inline(always)]
pub(crate) fn tool_pose_with<S: Isa>(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Pose {
    update_kinematics_with::<S>(robot, data, q);
    data.tool
}

multiversion! {
    /// [`forward_kinematics`] for DH robots.
    #[inline(always)]
    fn forward_kinematics_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Isometry3<f64> => forward_kinematics_with;
}

/// Tool pose in the base frame for joint positions `q` (seed eq. 1 chained, then
/// the tool transform). Every joint frame is left in `data` ([`ModelData::frame`]);
/// [`ModelData::tool_frame`] gives the same pose as a rotation matrix.
pub fn forward_kinematics(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Isometry3<f64> {
    if robot.general {
        crate::general::forward_kinematics(robot, data, q)
    } else {
        forward_kinematics_dh(robot, data, q)
    }
}

multiversion! {
    /// [`jacobian`] for DH robots.
    #[inline(always)]
    fn jacobian_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Jacobian => jacobian_with;
}

/// Geometric Jacobian of the tool frame origin in the base frame (rows
/// `vx vy vz wx wy wz`): column `j` is `[z_{j-1} × (p − o_{j-1}); z_{j-1}]` for a
/// revolute joint and `[z_{j-1}; 0]` for a prismatic one. Runs the forward
/// kinematics too (frames left in `data`).
pub fn jacobian(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Jacobian {
    if robot.general {
        crate::general::jacobian(robot, data, q)
    } else {
        jacobian_dh(robot, data, q)
    }
}

/// The Jacobian from the frames already in `data`.
#[inline(always)]
pub(crate) fn jacobian_from_frames(robot: &Robot, data: &ModelData) -> Jacobian {
    if robot.general {
        return crate::general::jacobian_from_frames(robot, data);
    }
    jacobian_of_frames(robot, data, robot.dof, robot.plain)
}

/// [`jacobian_from_frames`] for the first `n = dof` joints (`plain`: `robot.plain`).
#[inline(always)]
fn jacobian_of_frames(robot: &Robot, data: &ModelData, n: usize, plain: bool) -> Jacobian {
    let mut jac = Jacobian::zeros();
    let p = data.tool.translation;
    for j in 0..n.min(MAX_JOINTS) {
        let f = &data.frames[j];
        let z: Vector3<f64> = f.rotation.column(2).into_owned();
        if plain || robot.consts[j].revolute {
            let v = z.cross(&(p - f.translation));
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&v);
            jac.fixed_view_mut::<3, 1>(3, j).copy_from(&z);
        } else {
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&z);
        }
    }
    jac
}

/// Which task-space rows a dexterity measure looks at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskRows {
    /// All six rows (linear and angular velocity).
    Full,
    /// Linear velocity rows `vx vy vz`.
    Position,
    /// Angular velocity rows `wx wy wz`.
    Orientation,
    /// Planar arm in the base xy plane: `vx vy`.
    PlanarXy,
}

impl TaskRows {
    fn mask(self) -> [bool; 6] {
        match self {
            TaskRows::Full => [true; 6],
            TaskRows::Position => [true, true, true, false, false, false],
            TaskRows::Orientation => [false, false, false, true, true, true],
            TaskRows::PlanarXy => [true, true, false, false, false, false],
        }
    }
}

/// Singular-value summary of the Jacobian restricted to some rows and the
/// robot's `dof` columns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dexterity {
    /// Singular values, largest first; only the first `count` are meaningful.
    pub singular_values: [f64; 6],
    /// `min(rows, dof)`.
    pub count: usize,
    /// Yoshikawa manipulability `sqrt(det(J Jᵀ))` over the selected rows: the
    /// product of the singular values, 0 when `dof < rows`.
    pub manipulability: f64,
    /// `σ_max / σ_min` (infinite at a singularity).
    pub condition_number: f64,
    /// `σ_min`: distance to the nearest singularity.
    pub smallest_singular_value: f64,
    /// Number of singular values above `1e-9 · max(1, σ_max)`.
    pub rank: usize,
}

/// Singular-value analysis of `jac` restricted to `rows` and the first `dof`
/// columns. The seed arm has rank 5 of 6 everywhere (axes 1 and 2 collinear) and
/// rank 4 at `q5 = 0`.
pub fn dexterity(jac: &Jacobian, dof: usize, rows: TaskRows) -> Dexterity {
    let mask = rows.mask();
    let nrows = mask.iter().filter(|m| **m).count();
    let dof = dof.min(crate::MAX_JOINTS);
    // Rows not selected and columns beyond dof are zeroed: they add only zero
    // singular values, which are dropped below.
    let mut m = SMatrix::<f64, 8, 6>::zeros();
    for r in 0..6 {
        if mask[r] {
            for c in 0..dof {
                m[(c, r)] = jac[(r, c)];
            }
        }
    }
    let mut sv = [0.0; 6];
    let svd = m.svd_unordered(false, false);
    for (i, s) in svd.singular_values.iter().enumerate() {
        sv[i] = if s.is_finite() { *s } else { f64::NAN };
    }
    sv.sort_by(|a, b| b.total_cmp(a));
    let count = nrows.min(dof);
    let used = &sv[..count];
    let smax = used.first().copied().unwrap_or(0.0);
    let smin = used.last().copied().unwrap_or(0.0);
    let manipulability = if dof < nrows {
        0.0
    } else {
        used.iter().product()
    };
    let tol = 1e-9 * smax.max(1.0);
    Dexterity {
        singular_values: sv,
        count,
        manipulability,
        condition_number: if smin > 0.0 {
            smax / smin
        } else {
            f64::INFINITY
        },
        smallest_singular_value: smin,
        rank: used.iter().filter(|s| **s > tol).count(),
    }
}

/// Yoshikawa manipulability `sqrt(det(J Jᵀ))` over `rows` (see [`dexterity`]).
pub fn manipulability(jac: &Jacobian, dof: usize, rows: TaskRows) -> f64 {
    dexterity(jac, dof, rows).manipulability
}

/// Condition number `σ_max / σ_min` over `rows` (see [`dexterity`]).
pub fn condition_number(jac: &Jacobian, dof: usize, rows: TaskRows) -> f64 {
    dexterity(jac, dof, rows).condition_number
}

/// Smallest singular value over `rows` (see [`dexterity`]).
pub fn smallest_singular_value(jac: &Jacobian, dof: usize, rows: TaskRows) -> f64 {
    dexterity(jac, dof, rows).smallest_singular_value
}

/// Numerical rank over `rows` (see [`dexterity`]).
pub fn rank(jac: &Jacobian, dof: usize, rows: TaskRows) -> usize {
    dexterity(jac, dof, rows).rank
}

multiversion! {
    /// [`tool_pose`] for DH robots.
    #[inline(always)]
    fn tool_pose_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Pose => tool_pose_with;
}

/// Pose of every joint frame and the tool; convenience for callers that want the
/// homogeneous matrices (e.g. the eval interface).
pub fn tool_pose(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Pose {
    if robot.general {
        crate::general::tool_pose(robot, data, q)
    } else {
        tool_pose_dh(robot, data, q)
    }
}
