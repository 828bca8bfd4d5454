//! Composite-rigid-body algorithm for the joint-space mass matrix, in DH link
//! frames. Going from the tip to the base, the composite inertia of bodies
//! `i..n` is carried about each frame origin; in frame `i` joint `i` is the `z`
//! axis through the origin, so the composite's spatial force for unit joint
//! motion is read off directly and `M_ii` is one entry. That force is then
//! carried down the chain, giving `M_ki` for `k < i` as its `z` component.
//! The DH twist's signed permutations make most rotations free.

use crate::data::ModelData;
use crate::kinematics::update_joint_values;
use crate::math::joint_rot;
use crate::robot::{JointConst, Robot, Twist};
use crate::{JointVector, MassMatrix};
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

/// Joint-space mass matrix `M(q)` (the seed's `D_ij`, eq. 20) with rotor inertia
/// on the diagonal; symmetric, zero outside the `dof` block. Allocation-free.
pub fn mass_matrix(robot: &Robot, data: &mut ModelData, q: &JointVector) -> MassMatrix {
    update_joint_values(robot, data, q);
    mass_matrix_from_joint_values(robot, data);
    data.mass
}

/// CRBA on the joint values already in `data`; result in `data.mass`.
#[inline]
pub(crate) fn mass_matrix_from_joint_values(robot: &Robot, data: &mut ModelData) {
    let n = robot.dof;
    let mass = &mut data.mass;
    mass.fill(0.0);
    // Composite of bodies i..n about the origin of the frame it is expressed in.
    let mut m = 0.0;
    let mut h = Vector3::zeros();
    let mut inertia = Sym3::default();
    for i in (0..n).rev() {
        // Add body i (frame i+1, about its origin), then move the composite to frame i.
        let b = &robot.bodies[i];
        m += b.mass;
        h += b.h;
        inertia.add(&Sym3::from_matrix(&b.inertia_origin));
        let jc = &robot.consts[i];
        let (c, s, d) = (data.cos[i], data.sin[i], data.d[i]);
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
        let (mut moment, mut force) = if jc.revolute {
            (inertia.column_z(), Vector3::new(-h.y, h.x, 0.0))
        } else {
            (Vector3::new(h.y, -h.x, 0.0), Vector3::new(0.0, 0.0, m))
        };
        mass[(i, i)] = if jc.revolute { moment.z } else { force.z } + jc.rotor;
        // Carry it down the chain: frame k+1 → frame k.
        for k in (0..i).rev() {
            let jk = &robot.consts[k];
            let (ck, sk, dk) = (data.cos[k], data.sin[k], data.d[k]);
            let pk = Vector3::new(jk.a * ck, jk.a * sk, dk);
            force = joint_rot(jk, ck, sk, &force);
            moment = joint_rot(jk, ck, sk, &moment);
            if jk.offset {
                moment += pk.cross(&force);
            }
            let mki = if jk.revolute { moment.z } else { force.z };
            mass[(k, i)] = mki;
            mass[(i, k)] = mki;
        }
    }
}
