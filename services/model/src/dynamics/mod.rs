//! Rigid-body dynamics on the hot path: inverse dynamics by recursive
//! Newton-Euler ([`rnea`]), the mass matrix by the composite-rigid-body algorithm
//! ([`mass_matrix`]), and forward dynamics ([`forward_dynamics`]) by an `L D Lᵀ`
//! solve of `M qdd = tau − h`. The equation of motion is the seed's eq. 17 plus
//! actuator and friction terms:
//!
//! `tau = M(q) qdd + C(q, qd) qd + g(q) + I_rotor qdd + viscous·qd + coulomb·sign(qd)`
//!
//! with `M` including the rotor inertia on its diagonal and `sign(0) = 0`.
//! Torques are joint-side; divide by the gear ratio for motor torque
//! ([`crate::Joint::motor_torque`]).

pub(crate) mod crba;
pub(crate) mod forward;
pub(crate) mod rnea;

pub use crba::mass_matrix;
pub use forward::{DynamicsError, forward_dynamics, try_forward_dynamics};
pub use rnea::{coriolis_torque, gravity_torque, nonlinear_effects, rnea};

#[cfg(test)]
mod tests {
    use crate::{JointVector, ModelData, Robot};

    /// The hot paths specialised for `Robot::plain` arms (`isa::for_shape!`) give
    /// the same bits as the general path on the same robot (the seed arm, and the
    /// same arm with the specialisation switched off), and only plain arms take it.
    #[test]
    #[allow(clippy::needless_range_loop)] // s[k][i] reads like the state table
    fn plain_specialisation_equals_the_general_path_bit_for_bit() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots");
        let seed_arm = Robot::from_file(&dir.join("seed-arm.toml")).expect("seed arm");
        assert!(
            seed_arm.plain,
            "the seed arm is all revolute, diagonal, frictionless"
        );
        let prismatic = Robot::from_file(&dir.join("spherical-rrp.toml")).expect("RRP arm");
        assert!(!prismatic.plain, "a prismatic joint is not plain");
        let mut general = seed_arm.clone();
        general.plain = false;
        let all = |r: &Robot, s: &[JointVector; 3]| {
            let mut d = ModelData::new(r);
            let [q, qd, qdd] = s;
            let mut out = Vec::new();
            let mut bits = |v: &[f64]| out.extend(v.iter().map(|x| x.to_bits()));
            bits(super::rnea(r, &mut d, q, qd, qdd).as_slice());
            bits(super::nonlinear_effects(r, &mut d, q, qd).as_slice());
            bits(super::gravity_torque(r, &mut d, q).as_slice());
            bits(super::coriolis_torque(r, &mut d, q, qd).as_slice());
            bits(super::mass_matrix(r, &mut d, q).as_slice());
            bits(super::forward_dynamics(r, &mut d, q, qd, qdd).as_slice());
            out
        };
        let mut next = crate::test_support::uniform(0x2545_f491_4f6c_dd1d);
        for _ in 0..200 {
            let mut s = [JointVector::zeros(); 3];
            for i in 0..seed_arm.dof() {
                s[0][i] = (2.0 * next() - 1.0) * 4.0;
                s[1][i] = (2.0 * next() - 1.0) * 3.0;
                s[2][i] = (2.0 * next() - 1.0) * 5.0;
            }
            assert_eq!(all(&seed_arm, &s), all(&general, &s), "state {s:?}");
        }
    }
}
