//! The mechanics behind the drives' motors. All axes step together so a coupled model
//! (the arm's forward dynamics) can drive the whole chain; values are joint-side SI
//! units (rad, rad/s, N·m) and the drives convert to motor counts and per mille.

use microrobot_actuator::config::Integrator;
use microrobot_actuator::plant::ArmPlant;
use microrobot_model::{JointVector, MAX_JOINTS, Robot};

/// A plant of `axes()` joints, stepped once per process data exchange.
pub trait Plant: Send {
    /// Number of joints (one per drive).
    fn axes(&self) -> usize;
    /// Advances the plant by `dt_s` under the joint torques `torque_nm` (one per axis,
    /// held constant over the step). An axis with `braked[i]` set is held still (its
    /// drive's power stage is off and the holding brake is closed).
    fn step(&mut self, torque_nm: &[f64], braked: &[bool], dt_s: f64);
    /// Joint position of axis `i` (rad).
    fn position(&self, i: usize) -> f64;
    /// Joint velocity of axis `i` (rad/s).
    fn velocity(&self, i: usize) -> f64;
}

/// Independent axes, each a pure inertia with viscous damping: the trivial test plant,
/// `J·qdd = τ − b·qd`, integrated semi-implicitly.
#[derive(Debug, Clone)]
pub struct InertiaPlant {
    inertia_kg_m2: f64,
    damping_nm_s_per_rad: f64,
    q: Vec<f64>,
    qd: Vec<f64>,
}

impl InertiaPlant {
    /// `axes` joints at rest at 0, each of inertia `inertia_kg_m2` (positive) with a
    /// little damping (1 % of the inertia per second).
    pub fn new(axes: usize, inertia_kg_m2: f64) -> InertiaPlant {
        InertiaPlant {
            inertia_kg_m2,
            damping_nm_s_per_rad: 0.01 * inertia_kg_m2,
            q: vec![0.0; axes],
            qd: vec![0.0; axes],
        }
    }
}

impl Plant for InertiaPlant {
    fn axes(&self) -> usize {
        self.q.len()
    }

    fn step(&mut self, torque_nm: &[f64], braked: &[bool], dt_s: f64) {
        for i in 0..self.q.len() {
            if braked.get(i).copied().unwrap_or(true) {
                self.qd[i] = 0.0;
                continue;
            }
            let tau = torque_nm.get(i).copied().unwrap_or(0.0);
            let a = (tau - self.damping_nm_s_per_rad * self.qd[i]) / self.inertia_kg_m2;
            self.qd[i] += a * dt_s;
            self.q[i] += self.qd[i] * dt_s;
        }
    }

    fn position(&self, i: usize) -> f64 {
        self.q.get(i).copied().unwrap_or(0.0)
    }

    fn velocity(&self, i: usize) -> f64 {
        self.qd.get(i).copied().unwrap_or(0.0)
    }
}

/// The seed arm (config/robots/seed-arm.toml) moved by the simulated arm's own plant
/// ([`ArmPlant`]: the forward dynamics of `microrobot-model`, classic RK4, hard stops
/// at the joint limits) in substeps of at most 1 ms. Braked axes are held where they
/// are (the torque their brake takes is not modelled).
#[derive(Debug, Clone)]
pub struct SeedArmPlant {
    plant: ArmPlant,
}

/// The seed arm's description, built into the crate.
const SEED_ARM_TOML: &str = include_str!("../../../config/robots/seed-arm.toml");

/// The longest integration substep (s).
const MAX_SUBSTEP_S: f64 = 1e-3;

impl SeedArmPlant {
    /// The seed arm at rest at q = 0 (clamped into its limits).
    pub fn new() -> Result<SeedArmPlant, String> {
        let robot = Robot::from_toml_str(SEED_ARM_TOML, "seed-arm.toml")
            .map_err(|e| format!("seed arm description: {e}"))?;
        Ok(SeedArmPlant::from_robot(robot))
    }

    /// Any robot of the model crate (at most [`MAX_JOINTS`] joints), at rest at q = 0.
    pub fn from_robot(robot: Robot) -> SeedArmPlant {
        SeedArmPlant {
            plant: ArmPlant::new(robot, 0.0, 0.0, Integrator::Rk4, 1, &JointVector::zeros()),
        }
    }
}

impl Plant for SeedArmPlant {
    fn axes(&self) -> usize {
        self.plant.dof()
    }

    fn step(&mut self, torque_nm: &[f64], braked: &[bool], dt_s: f64) {
        let dof = self.plant.dof();
        let mut tau = JointVector::zeros();
        let mut held = [true; MAX_JOINTS];
        for i in 0..dof {
            tau[i] = torque_nm.get(i).copied().unwrap_or(0.0);
            held[i] = braked.get(i).copied().unwrap_or(true);
        }
        let substeps = (dt_s / MAX_SUBSTEP_S).ceil().clamp(1.0, 1000.0) as usize;
        for _ in 0..substeps {
            // A diverged step keeps the last good state (the arm stays put).
            let _ = self.plant.step(&tau, dt_s / substeps as f64, &held[..dof]);
        }
    }

    fn position(&self, i: usize) -> f64 {
        if i < MAX_JOINTS {
            self.plant.state().0[i]
        } else {
            0.0
        }
    }

    fn velocity(&self, i: usize) -> f64 {
        if i < MAX_JOINTS {
            self.plant.state().1[i]
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inertia_follows_the_closed_form() {
        let mut p = InertiaPlant::new(2, 0.5);
        for _ in 0..1000 {
            p.step(&[1.0, 1.0], &[false, true], 0.001);
        }
        // q = τ t² / (2 J) = 1 m... ignoring the tiny damping.
        assert!((p.position(0) - 1.0).abs() < 0.02, "{}", p.position(0));
        assert_eq!(p.position(1), 0.0);
    }

    #[test]
    fn seed_arm_falls_when_released_and_stays_when_braked() {
        let mut p = SeedArmPlant::new().expect("seed arm");
        assert_eq!(p.axes(), 6);
        p.step(&[0.0; 6], &[true; 6], 0.01);
        assert_eq!(p.position(1), 0.0);
        for _ in 0..100 {
            p.step(&[0.0; 6], &[false; 6], 0.001);
        }
        let moved = (0..6).any(|i| p.position(i).abs() > 1e-4);
        assert!(moved, "gravity moves the released arm");
    }
}
