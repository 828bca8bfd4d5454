//! The arm's rigid-body plant: the forward dynamics of a robot model integrated over
//! time, `qdd = M(q)⁻¹ (τ − h(q, qd) − τ_f(qd))` with `τ_f = b·qd + c·sign(qd)` the
//! viscous and Coulomb friction the plant has on top of the model. Classic RK4 or
//! semi-implicit Euler with equal substeps, the torque held constant over a step
//! (zero-order hold, like a drive's cyclic target torque), hard stops at the position
//! limits (velocity into the stop zeroed). Shared by the simulated arm and by any stand-in
//! for hardware that moves the same arm (the emulated EtherCAT drives).
//!
//! Allocation-free after construction.

use crate::config::Integrator;
use microrobot_model::{JointVector, MAX_JOINTS, ModelData, Robot, forward_dynamics};

/// Forward dynamics produced a non-finite state (a singular mass matrix, a runaway
/// torque); the plant kept its last good state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Diverged;

/// A robot model's rigid-body motion, stepped under joint torques.
#[derive(Debug, Clone)]
pub struct ArmPlant {
    robot: Robot,
    data: ModelData,
    dof: usize,
    q: JointVector,
    qd: JointVector,
    q_min: JointVector,
    q_max: JointVector,
    viscous_nms: f64,
    coulomb_nm: f64,
    integrator: Integrator,
    substeps: u32,
}

impl ArmPlant {
    /// `robot` at rest at `q0` (clamped into the joint limits), with extra viscous
    /// (N·m·s/rad) and Coulomb (N·m) friction on every joint, integrated with
    /// `integrator` in `substeps` (at least 1) equal substeps per [`ArmPlant::step`].
    pub fn new(
        robot: Robot,
        viscous_nms: f64,
        coulomb_nm: f64,
        integrator: Integrator,
        substeps: u32,
        q0: &JointVector,
    ) -> Self {
        let dof = robot.dof().min(MAX_JOINTS);
        let (q_min, q_max) = robot.position_limits();
        let mut q = JointVector::zeros();
        for (i, j) in robot.joints().iter().enumerate().take(dof) {
            q[i] = j.limits.clamp(q0[i]);
        }
        let data = ModelData::new(&robot);
        Self {
            robot,
            data,
            dof,
            q,
            qd: JointVector::zeros(),
            q_min,
            q_max,
            viscous_nms,
            coulomb_nm,
            integrator,
            substeps: substeps.max(1),
        }
    }

    /// The robot the plant moves.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Positions and velocities (rad or m, rad/s or m/s).
    pub fn state(&self) -> (JointVector, JointVector) {
        (self.q, self.qd)
    }

    /// Sets the state (tests, restarts).
    pub fn set_state(&mut self, q: &JointVector, qd: &JointVector) {
        self.q = *q;
        self.qd = *qd;
    }

    /// Brakes on: every joint stops where it is.
    pub fn stop(&mut self) {
        self.qd = JointVector::zeros();
    }

    #[inline]
    fn accel(&mut self, q: &JointVector, qd: &JointVector, tau: &JointVector) -> JointVector {
        let mut t = *tau;
        if self.viscous_nms != 0.0 || self.coulomb_nm != 0.0 {
            for i in 0..self.dof {
                let s = if qd[i] > 0.0 {
                    1.0
                } else if qd[i] < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                t[i] -= self.viscous_nms * qd[i] + self.coulomb_nm * s;
            }
        }
        forward_dynamics(&self.robot, &mut self.data, q, qd, &t)
    }

    /// Advances the plant by `dt` seconds under the constant torque `tau`; joints with
    /// `held[i]` set (brake closed) keep their position and rest at the end of each
    /// substep (the torque their brake takes is not modelled). On a non-finite result
    /// the plant keeps its state from before the call.
    pub fn step(&mut self, tau: &JointVector, dt: f64, held: &[bool]) -> Result<(), Diverged> {
        let (q_start, qd_start) = (self.q, self.qd);
        let h = dt / self.substeps as f64;
        for _ in 0..self.substeps {
            let (q, qd) = (self.q, self.qd);
            match self.integrator {
                Integrator::SemiImplicitEuler => {
                    let a = self.accel(&q, &qd, tau);
                    self.qd = qd + a * h;
                    self.q = q + self.qd * h;
                }
                Integrator::Rk4 => {
                    let k1v = qd;
                    let k1a = self.accel(&q, &qd, tau);
                    let q2 = q + k1v * (h / 2.0);
                    let v2 = qd + k1a * (h / 2.0);
                    let k2a = self.accel(&q2, &v2, tau);
                    let q3 = q + v2 * (h / 2.0);
                    let v3 = qd + k2a * (h / 2.0);
                    let k3a = self.accel(&q3, &v3, tau);
                    let q4 = q + v3 * h;
                    let v4 = qd + k3a * h;
                    let k4a = self.accel(&q4, &v4, tau);
                    self.q = q + (k1v + v2 * 2.0 + v3 * 2.0 + v4) * (h / 6.0);
                    self.qd = qd + (k1a + k2a * 2.0 + k3a * 2.0 + k4a) * (h / 6.0);
                }
            }
            for i in 0..self.dof {
                if held.get(i).copied().unwrap_or(false) {
                    self.q[i] = q[i];
                    self.qd[i] = 0.0;
                } else if self.q[i] < self.q_min[i] {
                    self.q[i] = self.q_min[i];
                    self.qd[i] = self.qd[i].max(0.0);
                } else if self.q[i] > self.q_max[i] {
                    self.q[i] = self.q_max[i];
                    self.qd[i] = self.qd[i].min(0.0);
                }
            }
        }
        if (0..self.dof).all(|i| self.q[i].is_finite() && self.qd[i].is_finite()) {
            Ok(())
        } else {
            self.q = q_start;
            self.qd = qd_start;
            Err(Diverged)
        }
    }
}
