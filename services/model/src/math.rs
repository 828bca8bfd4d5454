//! Numeric building blocks of the hot path: a fast sine/cosine pair, the two
//! elementary rotations of a DH step, and [`Pose`], a rigid transform kept as a
//! rotation matrix plus a translation (no quaternion round trips on the hot path).

use crate::robot::{JointConst, Sparsity, Twist};
use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

/// Rigid transform `x ↦ rotation · x + translation`; the rotation matrix is kept
/// as computed (orthonormal up to rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Rotation matrix (columns are the frame's axes in the parent frame).
    pub rotation: Matrix3<f64>,
    /// Origin of the frame in the parent frame, metres.
    pub translation: Vector3<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        rotation: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        translation: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Builds a pose from a translation (m) and roll-pitch-yaw angles (rad),
    /// `R = Rz(yaw) · Ry(pitch) · Rx(roll)` (the URDF convention).
    pub fn from_xyz_rpy(xyz: Vector3<f64>, rpy: Vector3<f64>) -> Pose {
        let rotation = *Rotation3::from_euler_angles(rpy.x, rpy.y, rpy.z).matrix();
        Pose {
            rotation,
            translation: xyz,
        }
    }

    /// Composition `self · other` (other expressed in self's frame).
    #[inline]
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose {
            rotation: self.rotation * other.rotation,
            translation: self.translation + self.rotation * other.translation,
        }
    }

    /// Maps a point given in this frame to the parent frame.
    #[inline]
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p + self.translation
    }

    /// 4×4 homogeneous matrix `[[R, t], [0, 1]]`.
    pub fn to_homogeneous(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rotation);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }

    /// The same transform as an [`Isometry3`] (rotation converted to a unit
    /// quaternion; exact up to rounding for an orthonormal matrix). nalgebra's
    /// branching Shepperd method measured faster here than a branch-free table
    /// lookup.
    #[inline(always)]
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.translation),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.rotation)),
        )
    }

    /// Converts an [`Isometry3`].
    pub fn from_isometry(iso: &Isometry3<f64>) -> Pose {
        Pose {
            rotation: *iso.rotation.to_rotation_matrix().matrix(),
            translation: iso.translation.vector,
        }
    }

    /// Origin as a point.
    pub fn origin(&self) -> Point3<f64> {
        Point3::from(self.translation)
    }
}

// Cody-Waite split of π/2 (33-bit pieces: k·PIO2_1 and k·PIO2_2 are exact for
// |k| < 2^20), the round-to-integer constant 1.5·2^52, and fdlibm's
// `__kernel_sin` / `__kernel_cos` minimax coefficients.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;
const PIO2_1: f64 = 1.5707963267341256;
const PIO2_2: f64 = 6.077100506303966e-11;
const PIO2_3: f64 = 2.0222662487111665e-21;
const S1: f64 = -0.16666666666666632;
const S2: f64 = 0.00833333333332249;
const S3: f64 = -0.0001984126982985795;
const S4: f64 = 2.7557313707070068e-06;
const S5: f64 = -2.5050760253406863e-08;
const S6: f64 = 1.58969099521155e-10;
const C1: f64 = 0.0416666666666666;
const C2: f64 = -0.001388888888887411;
const C3: f64 = 2.480158728947673e-05;
const C4: f64 = -2.7557314351390663e-07;
const C5: f64 = 2.087572321298175e-09;
const C6: f64 = -1.1359647557788195e-11;

/// `(sin x, cos x)`, accurate to about one ulp for `|x| < 1e5` (Cody-Waite
/// reduction by π/2 and fdlibm's minimax kernels), several times faster than two
/// libm calls. Larger or non-finite arguments fall back to [`f64::sin_cos`].
#[inline]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    if x.is_nan() || x.abs() >= 1.0e5 {
        return x.sin_cos();
    }
    // π/2 split in 33-bit pieces: k · PIO2_1 and k · PIO2_2 are exact for |k| < 2^20.
    let k = (x * std::f64::consts::FRAC_2_PI + ROUND_MAGIC) - ROUND_MAGIC;
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    let (s, c) = sin_cos_kernel(r);
    // Quadrant fix-up without branches (random angles would mispredict):
    // odd quadrants swap sin and cos, then signs follow bits of k and k + 1.
    let quadrant = k as i64 as u64;
    let swap = 0u64.wrapping_sub(quadrant & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    let sin = f64::from_bits(a ^ ((quadrant & 2) << 62));
    let cos = f64::from_bits(b ^ ((quadrant.wrapping_add(1) & 2) << 62));
    (sin, cos)
}

/// [`sin_cos`] of two angles at once in the two lanes of an SSE2 register (part
/// of the x86-64 baseline): the same reduction, kernels and quadrant fix-up,
/// bit for bit, at about half the cost per angle.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn sin_cos_pair(x0: f64, x1: f64) -> [(f64, f64); 2] {
    use std::arch::x86_64::*;
    if x0.is_nan() || x1.is_nan() || x0.abs() >= 1.0e5 || x1.abs() >= 1.0e5 {
        return [sin_cos(x0), sin_cos(x1)];
    }
    // SAFETY: SSE2 is part of the x86-64 baseline, so the intrinsics are always
    // available; the two stores write two f64 into arrays of two f64.
    unsafe {
        let splat = _mm_set1_pd;
        let mul = |a, b| _mm_mul_pd(a, b);
        let add = |a, b| _mm_add_pd(a, b);
        let sub = |a, b| _mm_sub_pd(a, b);
        let x = _mm_set_pd(x1, x0);
        let magic = splat(ROUND_MAGIC);
        let t = add(mul(x, splat(std::f64::consts::FRAC_2_PI)), magic);
        let k = sub(t, magic);
        let r = sub(
            sub(sub(x, mul(k, splat(PIO2_1))), mul(k, splat(PIO2_2))),
            mul(k, splat(PIO2_3)),
        );
        let z = mul(r, r);
        let ps = add(
            splat(S1),
            mul(
                z,
                add(
                    splat(S2),
                    mul(
                        z,
                        add(
                            splat(S3),
                            mul(z, add(splat(S4), mul(z, add(splat(S5), mul(z, splat(S6)))))),
                        ),
                    ),
                ),
            ),
        );
        let s = add(r, mul(mul(r, z), ps));
        let pc = mul(
            mul(z, z),
            add(
                splat(C1),
                mul(
                    z,
                    add(
                        splat(C2),
                        mul(
                            z,
                            add(
                                splat(C3),
                                mul(z, add(splat(C4), mul(z, add(splat(C5), mul(z, splat(C6)))))),
                            ),
                        ),
                    ),
                ),
            ),
        );
        let one = splat(1.0);
        let hz = mul(splat(0.5), z);
        let w = sub(one, hz);
        let c = add(w, add(sub(sub(one, w), hz), pc));
        // The low mantissa bits of t hold k in two's complement.
        let quadrant = _mm_castpd_si128(t);
        let one_i = _mm_set1_epi64x(1);
        let two_i = _mm_set1_epi64x(2);
        let swap = _mm_castsi128_pd(_mm_sub_epi64(
            _mm_setzero_si128(),
            _mm_and_si128(quadrant, one_i),
        ));
        let a = _mm_or_pd(_mm_andnot_pd(swap, s), _mm_and_pd(swap, c));
        let b = _mm_or_pd(_mm_andnot_pd(swap, c), _mm_and_pd(swap, s));
        let sign_s = _mm_castsi128_pd(_mm_slli_epi64(_mm_and_si128(quadrant, two_i), 62));
        let sign_c = _mm_castsi128_pd(_mm_slli_epi64(
            _mm_and_si128(_mm_add_epi64(quadrant, one_i), two_i),
            62,
        ));
        let sin = _mm_xor_pd(a, sign_s);
        let cos = _mm_xor_pd(b, sign_c);
        let mut so = [0.0; 2];
        let mut co = [0.0; 2];
        _mm_storeu_pd(so.as_mut_ptr(), sin);
        _mm_storeu_pd(co.as_mut_ptr(), cos);
        [(so[0], co[0]), (so[1], co[1])]
    }
}

/// [`sin_cos`] of `theta[..n]` four angles per AVX2 register, into `sin` and
/// `cos` (lanes beyond `n` in the last register are written too): the same
/// operations in the same order as [`sin_cos_pair`], so bit for bit the same
/// values. A group of four with a non-finite or huge angle falls back to
/// [`sin_cos`] lane by lane, exactly as the pair does.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn sin_cos_joints_avx2(
    n: usize,
    theta: &[f64; crate::MAX_JOINTS],
    sin: &mut [f64; crate::MAX_JOINTS],
    cos: &mut [f64; crate::MAX_JOINTS],
) {
    use std::arch::x86_64::*;
    for g in (0..n.min(crate::MAX_JOINTS)).step_by(4) {
        // SAFETY: AVX2 is enabled for this function (caller's contract); the
        // loads and stores touch the four f64 at `g..g + 4` of arrays of
        // MAX_JOINTS (a multiple of 4) f64.
        unsafe {
            let x = _mm256_loadu_pd(theta.as_ptr().add(g));
            // |x| < 1e5 in all four lanes (false for NaN), else lane by lane.
            let abs = _mm256_andnot_pd(_mm256_set1_pd(-0.0), x);
            let small = _mm256_cmp_pd::<_CMP_LT_OQ>(abs, _mm256_set1_pd(1.0e5));
            if _mm256_movemask_pd(small) != 0b1111 {
                for k in g..g + 4 {
                    (sin[k], cos[k]) = sin_cos(theta[k]);
                }
                continue;
            }
            // Macros, not closures: a closure would not inherit AVX2.
            macro_rules! splat {
                ($a:expr) => {
                    _mm256_set1_pd($a)
                };
            }
            macro_rules! mul {
                ($a:expr, $b:expr $(,)?) => {
                    _mm256_mul_pd($a, $b)
                };
            }
            macro_rules! add {
                ($a:expr, $b:expr $(,)?) => {
                    _mm256_add_pd($a, $b)
                };
            }
            macro_rules! sub {
                ($a:expr, $b:expr $(,)?) => {
                    _mm256_sub_pd($a, $b)
                };
            }
            let magic = splat!(ROUND_MAGIC);
            let t = add!(mul!(x, splat!(std::f64::consts::FRAC_2_PI)), magic);
            let k = sub!(t, magic);
            let r = sub!(
                sub!(sub!(x, mul!(k, splat!(PIO2_1))), mul!(k, splat!(PIO2_2))),
                mul!(k, splat!(PIO2_3)),
            );
            let z = mul!(r, r);
            let ps = add!(
                splat!(S1),
                mul!(
                    z,
                    add!(
                        splat!(S2),
                        mul!(
                            z,
                            add!(
                                splat!(S3),
                                mul!(
                                    z,
                                    add!(
                                        splat!(S4),
                                        mul!(z, add!(splat!(S5), mul!(z, splat!(S6))))
                                    )
                                ),
                            ),
                        ),
                    ),
                ),
            );
            let s = add!(r, mul!(mul!(r, z), ps));
            let pc = mul!(
                mul!(z, z),
                add!(
                    splat!(C1),
                    mul!(
                        z,
                        add!(
                            splat!(C2),
                            mul!(
                                z,
                                add!(
                                    splat!(C3),
                                    mul!(
                                        z,
                                        add!(
                                            splat!(C4),
                                            mul!(z, add!(splat!(C5), mul!(z, splat!(C6))))
                                        )
                                    ),
                                ),
                            ),
                        ),
                    ),
                ),
            );
            let one = splat!(1.0);
            let hz = mul!(splat!(0.5), z);
            let w = sub!(one, hz);
            let c = add!(w, add!(sub!(sub!(one, w), hz), pc));
            // The low mantissa bits of t hold k in two's complement.
            let quadrant = _mm256_castpd_si256(t);
            let one_i = _mm256_set1_epi64x(1);
            let two_i = _mm256_set1_epi64x(2);
            let swap = _mm256_castsi256_pd(_mm256_sub_epi64(
                _mm256_setzero_si256(),
                _mm256_and_si256(quadrant, one_i),
            ));
            let a = _mm256_or_pd(_mm256_andnot_pd(swap, s), _mm256_and_pd(swap, c));
            let b = _mm256_or_pd(_mm256_andnot_pd(swap, c), _mm256_and_pd(swap, s));
            let sign_s =
                _mm256_castsi256_pd(_mm256_slli_epi64(_mm256_and_si256(quadrant, two_i), 62));
            let sign_c = _mm256_castsi256_pd(_mm256_slli_epi64(
                _mm256_and_si256(_mm256_add_epi64(quadrant, one_i), two_i),
                62,
            ));
            _mm256_storeu_pd(sin.as_mut_ptr().add(g), _mm256_xor_pd(a, sign_s));
            _mm256_storeu_pd(cos.as_mut_ptr().add(g), _mm256_xor_pd(b, sign_c));
        }
    }
}

/// [`sin_cos`] of two angles (portable fallback).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn sin_cos_pair(x0: f64, x1: f64) -> [(f64, f64); 2] {
    [sin_cos(x0), sin_cos(x1)]
}

/// sin and cos on `[-π/4, π/4]` (fdlibm `__kernel_sin` / `__kernel_cos` coefficients).
#[inline]
fn sin_cos_kernel(r: f64) -> (f64, f64) {
    let z = r * r;
    let s = r + r * z * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    let pc = z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let c = w + (((1.0 - w) - hz) + pc);
    (s, c)
}

/// `Rᵀ v` for the DH rotation of joint `jc` (`R = Rz(θ) Rx(α)`, `(cos θ, sin θ)` given),
/// with the twist's signed permutation when `α` is 0 or ±90°.
#[inline(always)]
pub(crate) fn joint_rot_t(jc: &JointConst, c: f64, s: f64, v: &Vector3<f64>) -> Vector3<f64> {
    let ux = c * v.x + s * v.y;
    let uy = -s * v.x + c * v.y;
    match jc.twist {
        Twist::Zero => Vector3::new(ux, uy, v.z),
        Twist::PlusQuarter => Vector3::new(ux, v.z, -uy),
        Twist::MinusQuarter => Vector3::new(ux, -v.z, uy),
        Twist::General => Vector3::new(ux, jc.ca * uy + jc.sa * v.z, -jc.sa * uy + jc.ca * v.z),
    }
}

/// `R v` for the DH rotation of joint `jc` (see [`joint_rot_t`]).
#[inline(always)]
pub(crate) fn joint_rot(jc: &JointConst, c: f64, s: f64, v: &Vector3<f64>) -> Vector3<f64> {
    let (uy, uz) = match jc.twist {
        Twist::Zero => (v.y, v.z),
        Twist::PlusQuarter => (-v.z, v.y),
        Twist::MinusQuarter => (v.z, -v.y),
        Twist::General => (jc.ca * v.y - jc.sa * v.z, jc.sa * v.y + jc.ca * v.z),
    };
    Vector3::new(c * v.x - s * uy, s * v.x + c * uy, uz)
}

/// `u × p` for a `p` of sparsity `kind` (the products with its zero
/// components are skipped; the result equals `u.cross(p)`).
#[inline(always)]
pub(crate) fn cross_sparse(u: &Vector3<f64>, p: &Vector3<f64>, kind: Sparsity) -> Vector3<f64> {
    match kind {
        Sparsity::Zero => Vector3::zeros(),
        Sparsity::X => Vector3::new(0.0, u.z * p.x, -(u.y * p.x)),
        Sparsity::Y => Vector3::new(-(u.z * p.y), 0.0, u.x * p.y),
        Sparsity::Z => Vector3::new(u.y * p.z, -(u.x * p.z), 0.0),
        Sparsity::General => u.cross(p),
    }
}

/// `w × (w × p) + wd × p` (the acceleration of a point `p` fixed in a body
/// with angular velocity `w` and acceleration `wd`, relative to the origin),
/// for a `p` of sparsity `kind`. `w × p` has a zero where `p` has its only
/// non-zero component, so the outer cross product skips those terms too.
#[inline(always)]
pub(crate) fn point_accel(
    w: &Vector3<f64>,
    wd: &Vector3<f64>,
    p: &Vector3<f64>,
    kind: Sparsity,
) -> Vector3<f64> {
    let u = cross_sparse(w, p, kind);
    let centripetal = match kind {
        Sparsity::Zero => Vector3::zeros(),
        // u.x = 0
        Sparsity::X => Vector3::new(w.y * u.z - w.z * u.y, -(w.x * u.z), w.x * u.y),
        // u.y = 0
        Sparsity::Y => Vector3::new(w.y * u.z, w.z * u.x - w.x * u.z, -(w.y * u.x)),
        // u.z = 0
        Sparsity::Z => Vector3::new(-(w.z * u.y), w.z * u.x, w.x * u.y - w.y * u.x),
        Sparsity::General => w.cross(&u),
    };
    centripetal + cross_sparse(wd, p, kind)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_sin_cos_matches_libm_to_a_few_ulp() {
        let mut x = -60.0_f64;
        let mut worst = 0.0_f64;
        while x < 60.0 {
            let (s, c) = sin_cos(x);
            worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
            x += 0.000_731;
        }
        assert!(worst < 4.0e-16, "worst error {worst:e}");
        for x in [
            0.0,
            -0.0,
            1e-300,
            std::f64::consts::FRAC_PI_4,
            1e6,
            f64::NAN,
            f64::INFINITY,
        ] {
            let (s, c) = sin_cos(x);
            let (es, ec) = x.sin_cos();
            assert!(
                (s - es).abs() < 4.0e-16 || (s.is_nan() && es.is_nan()),
                "sin({x}) = {s}, libm {es}"
            );
            assert!(
                (c - ec).abs() < 4.0e-16 || (c.is_nan() && ec.is_nan()),
                "cos({x}) = {c}, libm {ec}"
            );
        }
    }

    #[test]
    fn paired_sin_cos_equals_the_scalar_one_bit_for_bit() {
        let mut x = -40.0_f64;
        while x < 40.0 {
            let y = 0.37 - 1.3 * x;
            let [a, b] = sin_cos_pair(x, y);
            assert_eq!(a, sin_cos(x), "x = {x}");
            assert_eq!(b, sin_cos(y), "y = {y}");
            x += 0.001_37;
        }
        let [a, b] = sin_cos_pair(f64::NAN, 2e6);
        assert!(a.0.is_nan() && a.1.is_nan());
        assert_eq!(b, 2e6_f64.sin_cos());
    }

    #[test]
    fn sparse_cross_products_equal_the_full_ones() {
        let w = Vector3::new(0.3, -1.7, 2.2);
        let wd = Vector3::new(-4.0, 0.6, 1.3);
        for p in [
            Vector3::zeros(),
            Vector3::new(0.05, 0.0, 0.0),
            Vector3::new(0.0, -0.036, 0.0),
            Vector3::new(0.0, 0.0, 0.0395),
            Vector3::new(0.1, -0.2, 0.3),
        ] {
            let kind = Sparsity::of(&p);
            assert_eq!(cross_sparse(&w, &p, kind), w.cross(&p), "p {p:?}");
            let full = w.cross(&w.cross(&p)) + wd.cross(&p);
            assert!((point_accel(&w, &wd, &p, kind) - full).norm() <= 1e-15 * (1.0 + full.norm()));
        }
    }

    #[test]
    fn joint_rotations_match_the_matrix_of_seed_eq_1_for_every_twist_class() {
        let th = 0.7_f64;
        for al in [
            0.0,
            std::f64::consts::FRAC_PI_2,
            -std::f64::consts::FRAC_PI_2,
            -1.2,
        ] {
            let r = Matrix3::new(
                th.cos(),
                -th.sin() * al.cos(),
                th.sin() * al.sin(),
                th.sin(),
                th.cos() * al.cos(),
                -th.cos() * al.sin(),
                0.0,
                al.sin(),
                al.cos(),
            );
            let jc = JointConst::with_twist(al);
            let v = Vector3::new(0.3, -1.1, 2.5);
            let (c, s) = (th.cos(), th.sin());
            assert!(
                (joint_rot(&jc, c, s, &v) - r * v).norm() < 1e-15,
                "alpha {al}"
            );
            assert!(
                (joint_rot_t(&jc, c, s, &v) - r.transpose() * v).norm() < 1e-15,
                "alpha {al}"
            );
        }
    }
}
