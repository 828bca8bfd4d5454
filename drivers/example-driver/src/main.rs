//! `microrobot-example-driver`: an actuator driver on the driver SDK, the template for a
//! real drive. The backend below is all a driver writes; the SDK's framework does the
//! bus, the lifecycle, the watchdogs, the safe state and the status.
//!
//! Its "hardware" is a rigid arm: the robot model's forward dynamics under the written
//! torque, integrated with semi-implicit Euler (no friction, noise or saturation), brakes
//! on while the drives are off. It reports a per-joint overspeed fault (code 0x8400, a
//! CiA 402 drive's velocity-controller error) like a drive would.
//!
//! ```text
//! microrobot-example-driver [--config FILE] [--instance NAME] [--rate-hz HZ] [--dof N] [--q0-deg a,b,..]
//! ```
//! `--dof`: the axes the hardware has (default: the robot's; another count is refused);
//! `--q0-deg`: where the arm starts (default: the start state the framework resolves).

use std::process::ExitCode;

use microrobot_driver::model::{ModelData, forward_dynamics};
use microrobot_driver::{ActuatorBackend, Args, Fault, JointVector, MAX_JOINTS, Measured, Robot};

const NAME: &str = "microrobot-example-driver";

/// The rigid arm.
struct RigidArm {
    robot: Robot,
    data: ModelData,
    dof: usize,
    q: JointVector,
    qd: JointVector,
    tau: JointVector,
    on: bool,
}

impl ActuatorBackend for RigidArm {
    fn dof(&self) -> usize {
        self.dof
    }
    fn on_activate(&mut self) -> Result<(), Fault> {
        self.on = true;
        Ok(())
    }
    fn on_deactivate(&mut self) -> Result<(), Fault> {
        (self.on, self.qd) = (false, JointVector::zeros());
        Ok(())
    }
    fn on_error(&mut self, _: &Fault) {
        (self.on, self.qd) = (false, JointVector::zeros());
    }
    fn write(&mut self, _now_ns: u64, dt: f64, tau: &JointVector) -> Result<(), Fault> {
        self.qd += forward_dynamics(&self.robot, &mut self.data, &self.q, &self.qd, tau) * dt;
        self.q += self.qd * dt;
        self.tau = *tau;
        for (i, j) in self.robot.joints().iter().enumerate() {
            if self.qd[i].is_nan() || self.qd[i].abs() > 2.0 * j.limits.velocity {
                return Err(Fault::joint(
                    i,
                    0x8400,
                    "overspeed (over 2× the velocity limit)",
                ));
            }
        }
        Ok(())
    }
    fn read(&mut self, _now_ns: u64) -> Result<Measured, Fault> {
        let tau_applied = if self.on {
            self.tau
        } else {
            JointVector::zeros()
        };
        Ok(Measured {
            q: self.q,
            qd: self.qd,
            tau_applied,
            saturated: false,
        })
    }
}

/// `--dof` and `--q0-deg`, checked before anything touches the bus.
fn options(args: &Args) -> Result<(Option<usize>, Option<Vec<f64>>), String> {
    let dof = args
        .value("--dof")
        .map(|v| {
            v.parse::<usize>()
                .ok()
                .filter(|d| (1..=MAX_JOINTS).contains(d))
                .ok_or(format!("--dof must be 1..={MAX_JOINTS}, got `{v}`"))
        })
        .transpose()?;
    let q0 = match args.value("--q0-deg") {
        Some(v) => {
            let q: Vec<f64> = v
                .split(',')
                .map(|s| s.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| format!("--q0-deg `{v}`: {e}"))?;
            if q.iter().any(|x| !x.is_finite()) {
                return Err(format!("--q0-deg `{v}`: values must be finite"));
            }
            Some(q)
        }
        None => None,
    };
    Ok((dof, q0))
}

fn main() -> ExitCode {
    let parsed = Args::from_env(&["--dof", "--q0-deg"]).and_then(|a| Ok((options(&a)?, a)));
    let ((dof, q0), args) = match parsed {
        Ok(p) => p,
        Err(e) => return microrobot_driver::usage_error(NAME, &e),
    };
    microrobot_driver::main(&args, |s| {
        let mut q = s.start.q;
        if let Some(deg) = &q0 {
            microrobot_driver::anyhow::ensure!(
                deg.len() == s.dof(),
                "--q0-deg has {} values, the robot {} joints",
                deg.len(),
                s.dof()
            );
            (0..deg.len()).for_each(|i| q[i] = deg[i].to_radians());
        }
        let robot = s.robot.clone();
        Ok(RigidArm {
            data: ModelData::new(&robot),
            robot,
            dof: dof.unwrap_or(s.dof()),
            q,
            qd: s.start.qd,
            tau: JointVector::zeros(),
            on: false,
        })
    })
}
