//! The simulated arm: an [`ActuatorBackend`] that integrates the forward dynamics of
//! the robot model, `qdd = M(q)⁻¹ (τ_sat − h(q, qd) − τ_f,extra(qd))`, with the
//! [`ArmPlant`] (`crate::plant`).
//!
//! * Integrator: classic RK4 (default) or semi-implicit Euler, with `substeps` equal
//!   steps of `period / substeps` per `write()`; the torque is held constant over the
//!   period (zero-order hold, like a drive's cyclic target torque).
//! * Torque saturation at each joint's effort limit (flagged in [`Measured::saturated`]).
//! * A deliberately wrong plant: `mass_scale` multiplies every link mass and inertia
//!   (1.1 = links 10 % heavier than the model the dynamics service uses), plus extra
//!   viscous and Coulomb friction the dynamics does not know.
//! * Hard stops at the position limits (the joint stops there, velocity into the stop zeroed).
//! * Gaussian sensor noise on q and qd from a seeded generator (same seed, same noise).
//! * Brakes: while the drives are off (before `on_activate`, after `on_deactivate` or a
//!   fault) the framework writes no torque, so the arm does not move.
//!
//! A plain [`ActuatorBackend`]: the lifecycle and its guards are the framework's.
//! Simulated time advances only in `write()`, one period per call: while the process is
//! frozen the simulated arm is frozen with it (see [`crate::ActuatorCore::on_wake`]).
//!
//! Allocation-free after construction.

use crate::config::SimConfig;
use microrobot_model::{JointVector, Robot};

use crate::backend::{ActuatorBackend, Fault, Measured};
use crate::plant::ArmPlant;

/// SplitMix64 + Box-Muller: a tiny deterministic Gaussian source.
#[derive(Debug, Clone)]
pub struct Gaussian {
    state: u64,
    spare: Option<f64>,
}

impl Gaussian {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed ^ 0x9E37_79B9_7F4A_7C15,
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1].
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    /// A standard normal sample.
    pub fn sample(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let u1 = self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let th = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * th.sin());
        r * th.cos()
    }
}

/// The simulated arm.
#[derive(Debug, Clone)]
pub struct SimArm {
    plant: ArmPlant,
    dof: usize,
    tau_applied: JointVector,
    saturated: bool,
    effort: JointVector,
    noise_q: f64,
    noise_qd: f64,
    rng: Gaussian,
    /// Drives on (between `on_activate` and `on_deactivate`/a fault): torque is applied.
    enabled: bool,
}

impl SimArm {
    /// A simulated copy of `model` (masses scaled by `cfg.mass_scale`) at rest at `q0`
    /// (clamped into the joint limits).
    pub fn new(model: &Robot, cfg: &SimConfig, q0: &JointVector) -> Self {
        let robot = if cfg.mass_scale == 1.0 {
            model.clone()
        } else {
            model.with_scaled_link_masses(cfg.mass_scale)
        };
        let dof = robot.dof();
        let mut effort = JointVector::zeros();
        for (i, j) in robot.joints().iter().enumerate() {
            effort[i] = j.limits.effort;
        }
        Self {
            plant: ArmPlant::new(
                robot,
                cfg.viscous_friction_nms,
                cfg.coulomb_friction_nm,
                cfg.integrator,
                cfg.substeps,
                q0,
            ),
            dof,
            tau_applied: JointVector::zeros(),
            saturated: false,
            effort,
            noise_q: cfg.sensor_noise_rad,
            noise_qd: cfg.sensor_noise_rad_s,
            rng: Gaussian::new(cfg.seed),
            enabled: false,
        }
    }

    /// The true (noise-free) state.
    pub fn true_state(&self) -> (JointVector, JointVector) {
        self.plant.state()
    }

    /// Sets the true state (tests, restarts).
    pub fn set_state(&mut self, q: &JointVector, qd: &JointVector) {
        self.plant.set_state(q, qd);
    }
}

/// The simulation's fault code: forward dynamics diverged (manufacturer-specific range
/// of the CiA 402 error codes).
pub const FAULT_DIVERGED: u32 = 0xFF01;

impl ActuatorBackend for SimArm {
    fn dof(&self) -> usize {
        self.dof
    }

    /// A late step integrates the same period: nothing on a bus misses it.
    fn cycle_may_run_late(&self) -> bool {
        true
    }

    fn on_activate(&mut self) -> Result<(), Fault> {
        self.enabled = true;
        Ok(())
    }

    fn on_deactivate(&mut self) -> Result<(), Fault> {
        // Brakes on: the arm stops where it is.
        self.plant.stop();
        self.enabled = false;
        Ok(())
    }

    fn on_error(&mut self, _fault: &Fault) {
        self.enabled = false;
    }

    fn on_reset(&mut self) -> Result<(), Fault> {
        self.plant.stop();
        Ok(())
    }

    fn write(&mut self, _now_ns: u64, period_s: f64, tau: &JointVector) -> Result<(), Fault> {
        let mut t = JointVector::zeros();
        self.saturated = false;
        for i in 0..self.dof {
            let lim = self.effort[i];
            let v = tau[i];
            t[i] = if v > lim {
                self.saturated = true;
                lim
            } else if v < -lim {
                self.saturated = true;
                -lim
            } else {
                v
            };
        }
        if self.plant.step(&t, period_s, &[]).is_err() {
            // The plant kept its last good state; the arm is "stuck" until a fault reset.
            return Err(Fault::drive(
                FAULT_DIVERGED,
                "forward dynamics diverged (singular mass matrix or non-finite state)",
            ));
        }
        self.tau_applied = t;
        Ok(())
    }

    fn read(&mut self, _now_ns: u64) -> Result<Measured, Fault> {
        let (q, qd) = self.plant.state();
        let mut m = Measured {
            q,
            qd,
            tau_applied: if self.enabled {
                self.tau_applied
            } else {
                JointVector::zeros()
            },
            saturated: self.saturated,
        };
        if self.noise_q > 0.0 || self.noise_qd > 0.0 {
            for i in 0..self.dof {
                m.q[i] += self.noise_q * self.rng.sample();
                m.qd[i] += self.noise_qd * self.rng.sample();
            }
        }
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Integrator;

    /// A pendulum: point mass 1 kg at 0.5 m, no gravity along the swing plane when
    /// gravity is zero; here gravity along −y with the arm along x.
    fn pendulum(gravity: f64) -> Robot {
        let text = format!(
            r#"
[robot]
name = "pendulum"
gravity_mps2 = [0.0, {gravity}, 0.0]
[[joints]]
name = "j1"
kind = "revolute"
dh = {{ theta_deg = 0.0, d_mm = 0.0, a_mm = 500.0, alpha_deg = 0.0 }}
limits = {{ min_deg = -720.0, max_deg = 720.0, vel_deg_s = 900.0, acc_deg_s2 = 900.0, jerk_deg_s3 = 9000.0, torque_nm = 20.0 }}
link = {{ mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }}
"#
        );
        Robot::from_toml_str(&text, "pendulum.toml").unwrap()
    }

    fn sim_cfg(integrator: Integrator, substeps: u32) -> SimConfig {
        SimConfig {
            integrator,
            substeps,
            ..SimConfig::default()
        }
    }

    fn active(robot: &Robot, cfg: &SimConfig) -> SimArm {
        let mut s = SimArm::new(robot, cfg, &JointVector::zeros());
        s.on_configure().unwrap();
        s.on_activate().unwrap();
        s
    }

    #[test]
    fn constant_torque_without_gravity_matches_the_closed_form() {
        // I = m l² = 0.25 kg·m²; τ = 1 N·m → qdd = 4 rad/s², q(t) = 2 t².
        let robot = pendulum(0.0);
        for (integ, tol) in [
            (Integrator::Rk4, 1e-12),
            (Integrator::SemiImplicitEuler, 5e-3),
        ] {
            let mut s = active(&robot, &sim_cfg(integ, 2));
            let mut tau = JointVector::zeros();
            tau[0] = 1.0;
            for _ in 0..1000 {
                s.write(0, 1e-3, &tau).unwrap();
            }
            let (q, qd) = s.true_state();
            assert!((q[0] - 2.0).abs() < tol, "{integ:?}: q = {}", q[0]);
            assert!((qd[0] - 4.0).abs() < 1e-9, "{integ:?}: qd = {}", qd[0]);
        }
    }

    #[test]
    fn rk4_small_oscillation_matches_the_pendulum_period() {
        // Gravity along −y, arm along +x at q = 0: hanging position is q = −π/2.
        // Small oscillation about it: θ'' = −(g/l) θ, ω = sqrt(9.81/0.5).
        let robot = pendulum(-9.81);
        let mut s = active(&robot, &sim_cfg(Integrator::Rk4, 1));
        let amp = 1e-3;
        let mut q = JointVector::zeros();
        q[0] = -std::f64::consts::FRAC_PI_2 + amp;
        s.set_state(&q, &JointVector::zeros());
        let omega = (9.81f64 / 0.5).sqrt();
        let dt = 1e-3;
        let n = 2000;
        for _ in 0..n {
            s.write(0, dt, &JointVector::zeros()).unwrap();
        }
        let expect = -std::f64::consts::FRAC_PI_2 + amp * (omega * dt * n as f64).cos();
        let (q, _) = s.true_state();
        // Nonlinearity at 1 mrad amplitude is ~amp³ scale; integrator error far below.
        assert!((q[0] - expect).abs() < 1e-8, "q {} vs {}", q[0], expect);
    }

    #[test]
    fn torque_saturates_at_the_effort_limit_and_is_flagged() {
        let robot = pendulum(0.0);
        let mut s = active(&robot, &sim_cfg(Integrator::Rk4, 1));
        let mut tau = JointVector::zeros();
        tau[0] = 100.0;
        s.write(0, 1e-3, &tau).unwrap();
        let m = s.read(0).unwrap();
        assert!(m.saturated);
        assert_eq!(m.tau_applied[0], 20.0);
    }

    #[test]
    fn inactive_arm_refuses_torque_and_stays_put() {
        let robot = pendulum(-9.81);
        let s = SimArm::new(&robot, &sim_cfg(Integrator::Rk4, 1), &JointVector::zeros());
        let mut l = crate::lifecycle::Lifecycle::new(s);
        l.configure().unwrap();
        assert!(!l.write(0, 1e-3, &JointVector::zeros()));
        assert_eq!(l.read(0).unwrap().q[0], 0.0);
    }

    #[test]
    fn noise_is_seeded_and_reproducible() {
        let robot = pendulum(0.0);
        let mut c = sim_cfg(Integrator::Rk4, 1);
        c.sensor_noise_rad = 1e-3;
        let mut a = active(&robot, &c);
        let mut b = active(&robot, &c);
        for _ in 0..10 {
            assert_eq!(a.read(0).unwrap(), b.read(0).unwrap());
        }
        assert_ne!(a.read(0).unwrap().q[0], 0.0);
    }

    #[test]
    fn heavier_links_accelerate_less() {
        let robot = pendulum(0.0);
        let mut c = sim_cfg(Integrator::Rk4, 1);
        c.mass_scale = 2.0;
        let mut s = active(&robot, &c);
        let mut tau = JointVector::zeros();
        tau[0] = 1.0;
        s.write(0, 1e-3, &tau).unwrap();
        let (_, qd) = s.true_state();
        assert!((qd[0] - 2e-3).abs() < 1e-12);
    }
}
