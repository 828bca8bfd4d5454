//! One teleoperation cycle, from a hand sample to a joint setpoint:
//!
//! 1. clutch: on engage the references are re-taken (the tool's commanded point and
//!    the hand's current position), so re-engaging continues from where the arm is;
//!    on release (or a stale master) the arm freezes: every joint takes its fastest
//!    jerk-limited stop and is held where it ends (no IK runs while disengaged, so the
//!    held joints cannot drift), and the tool's commanded point becomes the forward
//!    kinematics of that rest pose;
//! 2. scaling of the hand's displacement since engage (ratio, device frame → base);
//! 3. the tremor filter on the scaled displacement;
//! 4. Cartesian velocity/acceleration limits on the commanded tool point, the speed
//!    limit reduced near singularities (smallest singular value of the position
//!    Jacobian below `singularity_sigma_m`);
//! 5. IK (damped least squares, from the last accepted solution, no restarts); a
//!    solution that moves any joint by more than `flip_threshold_rad` in one cycle is
//!    refused (a configuration flip), a target the IK cannot reach within
//!    `workspace_tolerance_m` stops the tool at the last reachable point (the
//!    workspace edge or a joint limit) until the hand comes back inside;
//! 6. per joint, the jerk-limited generator from the current setpoint state towards
//!    the IK target ([`crate::JointTracker`]).
//!
//! Position only: the tool's orientation is left to the IK's least-squares solution
//! (the seed arm's Jacobian has rank 5, so a full pose cannot be commanded freely).

use microrobot_model::ik::{IkOptions, IkTarget, solve_local};
use microrobot_model::{JointVector, ModelData, Robot, forward_kinematics, jacobian};
use microrobot_trajectory::{KinematicLimits, Sample};
use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::flags;
use crate::{CartesianLimiter, JointTracker, MotionScaling, TremorFilter};

/// Teleoperation settings, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeleopSettings {
    /// Hand displacement / tool displacement.
    pub ratio: f64,
    /// Orientation of the master device's frame in the robot's base frame.
    pub frame: Rotation3<f64>,
    /// Tremor filter order (2, 4, 6, 8).
    pub filter_order: usize,
    /// Tremor filter cutoff (Hz).
    pub filter_cutoff_hz: f64,
    /// Tool speed limit (m/s).
    pub max_tool_velocity: f64,
    /// Tool acceleration limit (m/s²).
    pub max_tool_acceleration: f64,
    /// Below this smallest singular value of the position Jacobian (m/rad) the tool's
    /// speed limit shrinks in proportion (down to 10 %).
    pub singularity_sigma_m: f64,
    /// Largest joint change one IK solution may make in one cycle (rad); more is a flip.
    pub flip_threshold_rad: f64,
    /// IK residual (m) above which the target is outside the reachable workspace.
    pub workspace_tolerance_m: f64,
}

impl Default for TeleopSettings {
    fn default() -> Self {
        Self {
            ratio: 3.0,
            frame: Rotation3::identity(),
            filter_order: 4,
            filter_cutoff_hz: 4.0,
            max_tool_velocity: 0.05,
            max_tool_acceleration: 0.5,
            singularity_sigma_m: 0.01,
            flip_threshold_rad: 2f64.to_radians(),
            workspace_tolerance_m: 1e-5,
        }
    }
}

/// Why a teleop controller cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TeleopError {
    /// A setting is out of range.
    #[error("teleop setting {name} = {value} is not valid: {reason}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
    /// The tremor filter cannot be designed.
    #[error("tremor filter: {0}")]
    Filter(#[from] crate::tremor_filter::FilterError),
}

/// One master sample as the controller takes it (the caller checked freshness).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hand {
    /// Hand position in the device frame (m).
    pub position: Vector3<f64>,
    /// The clutch is engaged.
    pub clutch: bool,
}

/// The result of one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeleopStep {
    /// The joint setpoint.
    pub sample: Sample,
    /// Bit set of [`flags`].
    pub flags: u32,
    /// The commanded tool point after the Cartesian limits (m, base frame).
    pub tool_command: Vector3<f64>,
    /// The desired tool point before the limits (scaled, filtered hand motion).
    pub tool_desired: Vector3<f64>,
}

/// The teleoperation controller. Build it once; [`TeleopController::step`] allocates
/// nothing.
#[derive(Debug, Clone)]
pub struct TeleopController {
    robot: Robot,
    data: ModelData,
    settings: TeleopSettings,
    scaling: MotionScaling,
    filter: TremorFilter,
    limiter: CartesianLimiter,
    tracker: JointTracker,
    ik_options: IkOptions,
    /// The last accepted IK solution: the joint target and the IK seed.
    q_target: JointVector,
    /// The tool point of `q_target`.
    accepted_tool: Vector3<f64>,
    engaged: bool,
    hand_ref: Vector3<f64>,
    tool_ref: Vector3<f64>,
    hold_point: Vector3<f64>,
    last_hand: Option<Hand>,
    /// The desired tool point of the last cycle (for its velocity).
    last_desired: Vector3<f64>,
    dt: f64,
}

fn check(
    name: &'static str,
    value: f64,
    ok: bool,
    reason: &'static str,
) -> Result<(), TeleopError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(TeleopError::Setting {
            name,
            value,
            reason,
        })
    }
}

impl TeleopController {
    /// A controller for `robot` stepping every `dt` seconds, joints within `limits`,
    /// starting from the setpoint `start` (held until the clutch engages).
    pub fn new(
        robot: &Robot,
        settings: TeleopSettings,
        limits: &KinematicLimits,
        dt: f64,
        start: Sample,
    ) -> Result<Self, TeleopError> {
        let s = &settings;
        check("dt", dt, dt > 0.0, "> 0 s")?;
        check("ratio", s.ratio, s.ratio > 0.0, "> 0")?;
        check(
            "max_tool_velocity",
            s.max_tool_velocity,
            s.max_tool_velocity > 0.0,
            "> 0 m/s",
        )?;
        check(
            "max_tool_acceleration",
            s.max_tool_acceleration,
            s.max_tool_acceleration > 0.0,
            "> 0 m/s²",
        )?;
        check(
            "singularity_sigma_m",
            s.singularity_sigma_m,
            s.singularity_sigma_m >= 0.0,
            ">= 0 m/rad",
        )?;
        check(
            "flip_threshold_rad",
            s.flip_threshold_rad,
            s.flip_threshold_rad > 0.0,
            "> 0 rad",
        )?;
        check(
            "workspace_tolerance_m",
            s.workspace_tolerance_m,
            s.workspace_tolerance_m > 0.0,
            "> 0 m",
        )?;
        let scaling = MotionScaling::new(s.ratio, s.frame).ok_or(TeleopError::Setting {
            name: "ratio",
            value: s.ratio,
            reason: "> 0",
        })?;
        let filter = TremorFilter::butterworth(s.filter_order, s.filter_cutoff_hz, 1.0 / dt)?;
        let mut data = ModelData::new(robot);
        let tool = forward_kinematics(robot, &mut data, &start.q)
            .translation
            .vector;
        let mut c = Self {
            robot: robot.clone(),
            data,
            settings,
            scaling,
            filter,
            limiter: CartesianLimiter::new(tool, s.max_tool_velocity, s.max_tool_acceleration, dt),
            tracker: JointTracker::new(robot.dof(), limits, dt, start),
            ik_options: IkOptions {
                max_iterations: 20,
                position_tolerance_m: 1e-12,
                orientation_tolerance_rad: 1.0,
                restarts: 0,
                ..IkOptions::default()
            },
            q_target: start.q,
            accepted_tool: tool,
            engaged: false,
            hand_ref: Vector3::zeros(),
            tool_ref: tool,
            hold_point: tool,
            last_hand: None,
            last_desired: tool,
            dt,
        };
        c.restart(start);
        Ok(c)
    }

    /// The settings.
    pub fn settings(&self) -> &TeleopSettings {
        &self.settings
    }

    /// The tremor filter (its design and frequency response).
    pub fn filter(&self) -> &TremorFilter {
        &self.filter
    }

    /// Restarts from setpoint `start` (entering teleop mode): the tool holds there
    /// until the clutch engages.
    pub fn restart(&mut self, start: Sample) {
        let tool = forward_kinematics(&self.robot, &mut self.data, &start.q)
            .translation
            .vector;
        self.tracker.reset(start);
        self.q_target = start.q;
        self.accepted_tool = tool;
        self.limiter.stop_at(tool);
        self.engaged = false;
        self.tool_ref = tool;
        self.hold_point = tool;
        self.last_hand = None;
        self.last_desired = tool;
    }

    /// The joint tracker (its counters tell how often the linear law tracked).
    pub fn tracker(&self) -> &JointTracker {
        &self.tracker
    }

    /// The IK solution the joints are steered to (held while disengaged).
    pub fn joint_target(&self) -> &JointVector {
        &self.q_target
    }

    /// Whether the hand currently drives the tool.
    pub fn engaged(&self) -> bool {
        self.engaged
    }

    /// Smallest singular value of the position Jacobian at `q` (m/rad).
    fn position_sigma_min(&mut self, q: &JointVector) -> f64 {
        let j = jacobian(&self.robot, &mut self.data, q);
        let jp = j.fixed_rows::<3>(0);
        let jjt: Matrix3<f64> = jp * jp.transpose();
        jjt.symmetric_eigenvalues().min().max(0.0).sqrt()
    }

    /// One cycle. `hand` is the newest master sample, `None` when there is no fresh
    /// one (stale or absent master: the tool is brought to rest and held).
    pub fn step(&mut self, hand: Option<&Hand>) -> TeleopStep {
        let mut f = 0;
        let hand = match hand {
            Some(h) if h.position.iter().all(|v| v.is_finite()) => {
                self.last_hand = Some(*h);
                Some(*h)
            }
            Some(_) => {
                f |= flags::INPUT_REFUSED;
                self.last_hand
            }
            None => {
                f |= flags::MASTER_STALE;
                None
            }
        };
        let engage = hand.is_some_and(|h| h.clutch);
        let continuing = engage && self.engaged;
        if engage && !self.engaged {
            // Re-engage: continue from the commanded tool point and the current hand.
            if let Some(h) = hand {
                self.hand_ref = h.position;
            }
            self.tool_ref = self.limiter.position;
            self.filter.reset_to(Vector3::zeros());
        } else if !engage && self.engaged {
            // Freeze: the fastest stop of every joint, held there.
            self.q_target = self.tracker.stopping_point();
            self.hold_point = forward_kinematics(&self.robot, &mut self.data, &self.q_target)
                .translation
                .vector;
            self.limiter.stop_at(self.hold_point);
            self.accepted_tool = self.hold_point;
        }
        self.engaged = engage;
        let desired = match hand {
            Some(h) if engage => {
                let d = self
                    .scaling
                    .tool_displacement(&(h.position - self.hand_ref));
                self.tool_ref + self.filter.step(d)
            }
            _ => {
                f |= flags::CLUTCH_OPEN * u32::from(hand.is_some());
                self.hold_point
            }
        };
        if !self.engaged {
            // Disengaged: the joints stop and hold at `q_target` (set on release or at
            // restart); nothing the hand does moves them, and no Cartesian limit,
            // singularity measure or IK is needed for that.
            self.last_desired = desired;
            let sample = *self.tracker.step(&self.q_target, &JointVector::zeros());
            return TeleopStep {
                sample,
                flags: f,
                tool_command: self.limiter.position,
                tool_desired: desired,
            };
        }

        // Slow down near singularities.
        let q_now = self.tracker.state().q;
        let sigma = self.position_sigma_min(&q_now);
        let sigma_ref = self.settings.singularity_sigma_m;
        let speed_scale = if sigma_ref > 0.0 && sigma < sigma_ref {
            f |= flags::SINGULARITY;
            (sigma / sigma_ref).max(0.1)
        } else {
            1.0
        };
        // The desired point's velocity, while the hand drives it continuously.
        let desired_velocity = if continuing {
            (desired - self.last_desired) / self.dt
        } else {
            Vector3::zeros()
        };
        self.last_desired = desired;
        if self.limiter.step(&desired, &desired_velocity, speed_scale) {
            f |= flags::LIMITED;
        }
        let q_before = self.q_target;
        let mut moving_target = false;

        let target = IkTarget::Position(self.limiter.position);
        match solve_local(
            &self.robot,
            &mut self.data,
            &target,
            &self.q_target,
            &self.ik_options,
        ) {
            Ok(sol) => {
                let n = self.robot.dof();
                let jump = (0..n)
                    .map(|i| (sol.q[i] - self.q_target[i]).abs())
                    .fold(0.0, f64::max);
                if jump > self.settings.flip_threshold_rad {
                    f |= flags::FLIP_REFUSED;
                    self.limiter.stop_at(self.accepted_tool);
                } else if !sol.converged
                    && sol.position_error_m > self.settings.workspace_tolerance_m
                {
                    // Beyond the reachable workspace: stop at the last reachable point.
                    f |= flags::WORKSPACE_EDGE;
                    self.limiter.stop_at(self.accepted_tool);
                } else {
                    self.q_target = sol.q;
                    self.accepted_tool = self.limiter.position;
                    moving_target = true;
                }
            }
            Err(_) => {
                // Only non-finite values get here; never move towards them.
                f |= flags::INPUT_REFUSED;
                self.limiter.stop_at(self.accepted_tool);
            }
        }
        let q_velocity = if moving_target {
            (self.q_target - q_before) / self.dt
        } else {
            JointVector::zeros()
        };
        let sample = *self.tracker.step(&self.q_target, &q_velocity);
        TeleopStep {
            sample,
            flags: f,
            tool_command: self.limiter.position,
            tool_desired: desired,
        }
    }
}
