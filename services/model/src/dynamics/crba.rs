//! Composite-rigid-body algorithm for the joint-space mass matrix, in DH link
//! frames. Going from the tip to the base, the composite inertia of bodies
//! `i..n` is carried about each frame origin; in frame `i` joint `i` is the `z`
//! axis through the origin, so the composite's spatial force for unit joint
//! motion is read off directly and `M_ii` is one entry. That force is then
//! carried down the chain, giving `M_ki` for `k < i` as its `z` component.
//! The DH twist's signed permutations make most rotations free.

use crate::data::ModelData;
use crate::isa::{Isa, for_shape, multiversion};
use crate::kinematics::update_joint_values;
use crate::math::joint_rot;
use crate::robot::{JointConst, Robot, Twist};
use crate::{JointVector, MAX_JOINTS, MassMatrix};
use nalgebra::Vector3;

/// Symmetric 3×3 matrix by its six distinct entries.
#[derive(Clone, Copy, Debug, Default)]
struct Sym3 {
    xx: f64,
    yy: f64,
    zz: f64,
    xy: f64,
    xz: f64,
    yz: f64,
}

impl Sym3 {
    fn from_matrix(m: &nalgebra::Matrix3<f64>) -> Sym3 {
        Sym3 {
            xx: m[(0, 0)],
            yy: m[(1, 1)],
            zz: m[(2, 2)],
            xy: m[(0, 1)],
            xz: m[(0, 2)],
            yz: m[(1, 2)],
        }
    }

    fn add(&mut self, o: &Sym3) {
        self.xx += o.xx;
        self.yy += o.yy;
        self.zz += o.zz;
        self.xy += o.xy;
        self.xz += o.xz;
        self.yz += o.yz;
    }

    /// `Rx(α) S Rx(α)ᵀ`.
    #[inline(always)]
    fn rotate_x(&self, jc: &JointConst) -> Sym3 {
        let s = self;
        match jc.twist {
            Twist::Zero => *s,
            // Rx(+90°): new y = −old z, new z = old y.
            Twist::PlusQuarter => Sym3 {
                xx: s.xx,
                yy: s.zz,
                zz: s.yy,
                xy: -s.xz,
                xz: s.xy,
                yz: -s.yz,
            },
            // Rx(−90°): new y = old z, new z = −old y.
            Twist::MinusQuarter => Sym3 {
                xx: s.xx,
                yy: s.zz,
                zz: s.yy,
                xy: s.xz,
                xz: -s.xy,
                yz: -s.yz,
            },
            Twist::General => {
                let (c, sn) = (jc.ca, jc.sa);
                Sym3 {
                    xx: s.xx,
                    yy: c * c * s.yy - 2.0 * c * sn * s.yz + sn * sn * s.zz,
                    zz: sn * sn * s.yy + 2.0 * c * sn * s.yz + c * c * s.zz,
                    xy: c * s.xy - sn * s.xz,
                    xz: sn * s.xy + c * s.xz,
                    yz: c * sn * (s.yy - s.zz) + (c * c - sn * sn) * s.yz,
                }
            }
        }
    }

    /// `Rz(θ) S Rz(θ)ᵀ` for `(cos θ, sin θ)`.
    #[inline(always)]
    fn rotate_z(&self, c: f64, sn: f64) -> Sym3 {
        let s = self;
        let cs = c * sn;
        let (cc, ss) = (c * c, sn * sn);
        Sym3 {
            xx: cc * s.xx - 2.0 * cs * s.xy + ss * s.yy,
            yy: ss * s.xx + 2.0 * cs * s.xy + cc * s.yy,
            zz: s.zz,
            xy: cs * (s.xx - s.yy) + (cc - ss) * s.xy,
            xz: c * s.xz - sn * s.yz,
            yz: sn * s.xz + c * s.yz,
        }
    }

    /// `S e_z`.
    fn column_z(&self) -> Vector3<f64> {
        Vector3::new(self.xz, self.yz, self.zz)
    }
}

#[inline(always)]
pub(crate) fn mass_matrix_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> MassMatrix {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        mass_matrix_from_joint_values(robot, data, n, plain)
    });
    data.mass
}

multiversion! {
    /// [`mass_matrix`] for DH robots.
    #[inline(always)]
    fn mass_matrix_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) -> MassMatrix => mass_matrix_with;
}

/// Joint-space mass matrix `M(q)` (the seed's `D_ij`, eq. 20) with rotor inertia
/// on the diagonal; symmetric, zero outside the `dof` block. Allocation-free.
pub fn mass_matrix(robot: &Robot, data: &mut ModelData, q: &JointVector) -> MassMatrix {
    if robot.general {
        crate::general::mass_matrix(robot, data, q)
    } else {
        mass_matrix_dh(robot, data, q)
    }
}

/// `p × f` for `p = (a cos θ, a sin θ, d)`, the origin of frame `k + 1` in
/// frame `k`, skipping the zero `a` or `d` of most DH rows.
#[inline(always)]
fn offset_cross(a: f64, c: f64, s: f64, d: f64, f: &Vector3<f64>) -> Vector3<f64> {
    let mut m = if d != 0.0 {
        Vector3::new(-(d * f.y), d * f.x, 0.0)
    } else {
        Vector3::zeros()
    };
    if a != 0.0 {
        let (px, py) = (a * c, a * s);
        m += Vector3::new(py * f.z, -(px * f.z), px * f.y - py * f.x);
    }
    m
}

/// One step of carrying the pending mass-matrix columns down the chain: from
/// frame `joint + 1` to frame `joint` (rotation `Rz(θ) Rx(α)`, origin shift
/// `p = (a cos θ, a sin θ, d)`), reading off `M[joint][j]`.
struct CarryColumns {
    joint: usize,
    dof: usize,
    a: f64,
    c: f64,
    s: f64,
    d: f64,
    offset: bool,
    revolute: bool,
}

impl CarryColumns {
    /// `rot_x` applies `Rx(α)`; the rest of the rotation is the 2-D `Rz(θ)`.
    #[inline(always)]
    fn run(
        &self,
        mass: &mut MassMatrix,
        col_force: &mut [Vector3<f64>; MAX_JOINTS],
        col_moment: &mut [Vector3<f64>; MAX_JOINTS],
        rot_x: impl Fn(&Vector3<f64>) -> Vector3<f64>,
    ) {
        let (c, s, i) = (self.c, self.s, self.joint);
        let rot = |v: &Vector3<f64>| {
            let u = rot_x(v);
            Vector3::new(c * u.x - s * u.y, s * u.x + c * u.y, u.z)
        };
        for j in (i + 1)..self.dof {
            let force = rot(&col_force[j]);
            let mut moment = rot(&col_moment[j]);
            if self.offset {
                moment += offset_cross(self.a, c, s, self.d, &force);
            }
            let mij = if self.revolute { moment.z } else { force.z };
            mass[(i, j)] = mij;
            mass[(j, i)] = mij;
            col_force[j] = force;
            col_moment[j] = moment;
        }
    }
}

/// CRBA on the joint values already in `data`; result in `data.mass` (`plain`:
/// `robot.plain`, every joint revolute).
///
/// The columns `M_{·j}` of the joints beyond the current one are carried down
/// the chain together, one joint at a time: they are independent, so the CPU
/// overlaps them instead of waiting on one column's chain of rotations.
#[inline(always)]
pub(crate) fn mass_matrix_from_joint_values(
    robot: &Robot,
    data: &mut ModelData,
    n: usize,
    plain: bool,
) {
    let n = n.min(MAX_JOINTS);
    let mass = &mut data.mass;
    *mass = MassMatrix::zeros();
    // Composite of bodies i..n about the origin of the frame it is expressed in.
    let mut m = 0.0;
    let mut h = Vector3::zeros();
    let mut inertia = Sym3::default();
    // Spatial force (moment about the frame origin, force) of column j's unit
    // motion, for the columns j > i, in frame i + 1.
    let mut col_moment = [Vector3::zeros(); MAX_JOINTS];
    let mut col_force = [Vector3::zeros(); MAX_JOINTS];
    for i in (0..n).rev() {
        let jc = &robot.consts[i];
        let revolute = plain || jc.revolute;
        let (c, s, d) = (data.cos[i], data.sin[i], data.d[i]);
        // Carry the pending columns from frame i + 1 to frame i, with the twist's
        // rotation chosen once for all of them.
        let carry = CarryColumns {
            joint: i,
            dof: n,
            a: jc.a,
            c,
            s,
            d,
            offset: jc.offset,
            revolute,
        };
        match jc.twist {
            Twist::Zero => carry.run(mass, &mut col_force, &mut col_moment, |v| *v),
            Twist::PlusQuarter => carry.run(mass, &mut col_force, &mut col_moment, |v| {
                Vector3::new(v.x, -v.z, v.y)
            }),
            Twist::MinusQuarter => carry.run(mass, &mut col_force, &mut col_moment, |v| {
                Vector3::new(v.x, v.z, -v.y)
            }),
            Twist::General => carry.run(mass, &mut col_force, &mut col_moment, |v| {
                Vector3::new(v.x, jc.ca * v.y - jc.sa * v.z, jc.sa * v.y + jc.ca * v.z)
            }),
        }
        // Add body i (frame i+1, about its origin), then move the composite to frame i.
        let b = &robot.bodies[i];
        m += b.mass;
        h += b.h;
        inertia.add(&Sym3::from_matrix(&b.inertia_origin));
        let hr = joint_rot(jc, c, s, &h);
        let ir = inertia.rotate_x(jc).rotate_z(c, s);
        if !jc.offset {
            inertia = ir;
            h = hr;
        } else {
            // Shift from O_{i+1} to O_i, p = O_{i+1} in frame i:
            // I_A = I_B + 2(h·p) 1 − (h pᵀ + p hᵀ) + m(|p|² 1 − p pᵀ).
            let p = Vector3::new(jc.a * c, jc.a * s, d);
            let hp = hr.dot(&p);
            let pp = p.norm_squared();
            let diag = 2.0 * hp + m * pp;
            inertia = Sym3 {
                xx: ir.xx + diag - 2.0 * hr.x * p.x - m * p.x * p.x,
                yy: ir.yy + diag - 2.0 * hr.y * p.y - m * p.y * p.y,
                zz: ir.zz + diag - 2.0 * hr.z * p.z - m * p.z * p.z,
                xy: ir.xy - (hr.x * p.y + p.x * hr.y) - m * p.x * p.y,
                xz: ir.xz - (hr.x * p.z + p.x * hr.z) - m * p.x * p.z,
                yz: ir.yz - (hr.y * p.z + p.y * hr.z) - m * p.y * p.z,
            };
            h = hr + p * m;
        }
        // Spatial force of the composite for unit motion of joint i (z axis of
        // frame i): moment about O_i and force.
        let (moment, force) = if revolute {
            (inertia.column_z(), Vector3::new(-h.y, h.x, 0.0))
        } else {
            (Vector3::new(h.y, -h.x, 0.0), Vector3::new(0.0, 0.0, m))
        };
        mass[(i, i)] = if revolute { moment.z } else { force.z } + jc.rotor;
        col_force[i] = force;
        col_moment[i] = moment;
    }
}
