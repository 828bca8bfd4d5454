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
