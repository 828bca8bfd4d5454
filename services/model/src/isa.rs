//! Run-time instruction-set dispatch for the hot path.
//!
//! The hot-path algorithms are written once, generic over an [`Isa`], and
//! compiled twice: for the x86-64 baseline (SSE2) and, inside a
//! `#[target_feature(enable = "avx2")]` function, for AVX2 (three-operand VEX
//! encoding, 256-bit lanes). The CPU is asked once ([`has_avx2`]) and the AVX2
//! build runs where it can. Both builds perform the same IEEE operations in the
//! same order (no fused multiply-add, which would round differently; Rust never
//! contracts `a * b + c` on its own), so their results are bit-identical and a
//! lockstep simulation reproduces across hosts.

use crate::MAX_JOINTS;

/// The joint-angle sine/cosine evaluation that differs between the builds.
pub(crate) trait Isa {
    /// `(sin θ_i, cos θ_i)` for the first `n` of the angles (`n <= MAX_JOINTS`;
    /// entries beyond `n` may be written too).
    fn sin_cos_joints(
        n: usize,
        theta: &[f64; MAX_JOINTS],
        sin: &mut [f64; MAX_JOINTS],
        cos: &mut [f64; MAX_JOINTS],
    );
}

/// The x86-64 baseline (or any other architecture): two angles per SSE2 register.
pub(crate) struct Baseline;

impl Isa for Baseline {
    #[inline(always)]
    fn sin_cos_joints(
        n: usize,
        theta: &[f64; MAX_JOINTS],
        sin: &mut [f64; MAX_JOINTS],
        cos: &mut [f64; MAX_JOINTS],
    ) {
        for k in (0..n.min(MAX_JOINTS)).step_by(2) {
            let [a, b] = crate::math::sin_cos_pair(theta[k], theta[k + 1]);
            (sin[k], cos[k]) = a;
            (sin[k + 1], cos[k + 1]) = b;
        }
    }
}

/// AVX2: four angles per 256-bit register (bit-identical to [`Baseline`]).
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Isa for Avx2 {
    #[inline(always)]
    fn sin_cos_joints(
        n: usize,
        theta: &[f64; MAX_JOINTS],
        sin: &mut [f64; MAX_JOINTS],
        cos: &mut [f64; MAX_JOINTS],
    ) {
        // SAFETY: `Avx2` is only used inside functions compiled with AVX2
        // enabled, which run only after `has_avx2` said the CPU has it.
        unsafe { crate::math::sin_cos_joints_avx2(n, theta, sin, cos) }
    }
}

/// Whether this CPU runs the AVX2 build (asked once, then cached by std).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn has_avx2() -> bool {
    std::is_x86_feature_detected!("avx2")
}

/// Defines `pub fn $name(args) -> ret` that runs `$imp::<Avx2>` where the CPU
/// has AVX2 and `$imp::<Baseline>` otherwise. `$imp` must be
/// `#[inline(always)]` so that its whole body is compiled for the feature.
macro_rules! multiversion {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? => $imp:ident;) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $imp::<$crate::isa::Avx2>($($arg),*)
                }
                if $crate::isa::has_avx2() {
                    // SAFETY: the CPU has AVX2 (checked at run time just above).
                    return unsafe { avx2($($arg),*) };
                }
            }
            $imp::<$crate::isa::Baseline>($($arg),*)
        }
    };
}
pub(crate) use multiversion;

/// Evaluates `$body` with `$n` bound to the joint count and `$plain` to
/// `Robot::plain` (every joint revolute, no products of inertia about the frame
/// origins, no friction): as constants for six-joint arms, (6, true) for plain ones
/// like the seed arm and (6, false) for the others, so that the compiler unrolls
/// every joint loop, drops their bounds checks and, for plain arms, the branches for
/// prismatic joints, full inertia tensors and friction; as run-time values otherwise.
macro_rules! for_shape {
    ($robot:expr, |$n:ident, $plain:ident| $body:expr) => {
        match ($robot.dof, $robot.plain) {
            (6, true) => {
                let ($n, $plain): (usize, bool) = (6, true);
                $body
            }
            (6, false) => {
                let ($n, $plain): (usize, bool) = (6, false);
                $body
            }
            (dof, plain) => {
                let ($n, $plain): (usize, bool) = (dof, plain);
                $body
            }
        }
    };
}
pub(crate) use for_shape;

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::{Avx2, Baseline, has_avx2};
    use crate::dynamics::{crba, forward, rnea};
    use crate::{JointVector, ModelData, Robot, kinematics};

    /// The AVX2 build against the baseline build of every entry point, bit for
    /// bit, on robots with revolute and prismatic joints, offsets, tool, payload
    /// and friction, DH rows and placed joints, including angles that take the
    /// large-argument fallback.
    #[test]
    #[allow(clippy::needless_range_loop)] // s[k][i] reads like the state table
    fn avx2_build_equals_the_baseline_bit_for_bit() {
        if !has_avx2() {
            eprintln!("CPU without AVX2: nothing to compare");
            return;
        }
        #[target_feature(enable = "avx2")]
        fn all_avx2(r: &Robot, d: &mut ModelData, s: &[JointVector; 3]) -> Vec<f64> {
            all::<Avx2>(r, d, s)
        }
        #[inline(always)]
        fn all<S: super::Isa>(r: &Robot, d: &mut ModelData, s: &[JointVector; 3]) -> Vec<f64> {
            if r.is_placed() {
                return all_placed::<S>(r, d, s);
            }
            let [q, qd, qdd] = s;
            let mut out: Vec<f64> = Vec::new();
            let iso = kinematics::forward_kinematics_with::<S>(r, d, q);
            out.extend(iso.to_homogeneous().iter());
            out.extend(kinematics::jacobian_with::<S>(r, d, q).iter());
            out.extend(
                kinematics::tool_pose_with::<S>(r, d, q)
                    .to_homogeneous()
                    .iter(),
            );
            for i in 0..=r.dof() {
                out.extend(d.frame(i).to_homogeneous().iter());
            }
            out.extend(rnea::rnea_with::<S>(r, d, q, qd, qdd).iter());
            out.extend(rnea::nonlinear_effects_with::<S>(r, d, q, qd).iter());
            out.extend(rnea::gravity_torque_with::<S>(r, d, q).iter());
            out.extend(rnea::coriolis_torque_with::<S>(r, d, q, qd).iter());
            out.extend(crba::mass_matrix_with::<S>(r, d, q).iter());
            out.extend(forward::forward_dynamics_with::<S>(r, d, q, qd, qdd).iter());
            out
        }
        #[inline(always)]
        fn all_placed<S: super::Isa>(
            r: &Robot,
            d: &mut ModelData,
            s: &[JointVector; 3],
        ) -> Vec<f64> {
            use crate::general as g;
            let [q, qd, qdd] = s;
            let mut out: Vec<f64> = Vec::new();
            let iso = g::forward_kinematics_with::<S>(r, d, q);
            out.extend(iso.to_homogeneous().iter());
            out.extend(g::jacobian_with::<S>(r, d, q).iter());
            out.extend(g::tool_pose_with::<S>(r, d, q).to_homogeneous().iter());
            for i in 0..=r.dof() {
                out.extend(d.frame(i).to_homogeneous().iter());
            }
            out.extend(g::rnea_with::<S>(r, d, q, qd, qdd).iter());
            out.extend(g::nonlinear_effects_with::<S>(r, d, q, qd).iter());
            out.extend(g::gravity_torque_with::<S>(r, d, q).iter());
            out.extend(g::coriolis_torque_with::<S>(r, d, q, qd).iter());
            out.extend(g::mass_matrix_with::<S>(r, d, q).iter());
            out.extend(g::forward_dynamics_with::<S>(r, d, q, qd, qdd).iter());
            out
        }
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut next = crate::test_support::uniform(0x9e37_79b9_7f4a_7c15);
        for file in [
            "config/robots/seed-arm.toml",
            "config/robots/spherical-rrp.toml",
            "config/robots/planar-2r.toml",
            // placed joints (the general path): revolute, continuous, prismatic
            "tests/reference/urdf/test_arm.toml",
        ] {
            let robot = Robot::from_file(&dir.join(file)).unwrap_or_else(|e| panic!("{e}"));
            let mut data = ModelData::new(&robot);
            for case in 0..200 {
                let mut s = [JointVector::zeros(); 3];
                for i in 0..robot.dof() {
                    s[0][i] = (2.0 * next() - 1.0) * if case % 50 == 7 { 3e5 } else { 4.0 };
                    s[1][i] = (2.0 * next() - 1.0) * 3.0;
                    s[2][i] = (2.0 * next() - 1.0) * 5.0;
                }
                let base = all::<Baseline>(&robot, &mut data, &s);
                // SAFETY: the CPU has AVX2 (checked above).
                let wide = unsafe { all_avx2(&robot, &mut data, &s) };
                assert_eq!(base.len(), wide.len());
                for (k, (a, b)) in base.iter().zip(&wide).enumerate() {
                    assert!(
                        a.to_bits() == b.to_bits(),
                        "{file} case {case} output {k}: {a:e} vs {b:e}"
                    );
                }
            }
        }
    }
}
