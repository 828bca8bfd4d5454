//! The planner service: the clock of the pipeline. Every tick it samples the active
//! motion and publishes one joint setpoint (q, q̇, q̈, jerk).
//!
//! * Clock: its own timerfd at `rate_hz` on absolute deadlines (default), or, in
//!   lockstep, one tick per measured-state message from the actuator (not on its
//!   `FINAL` state: that repeats the last period's tick as the actuator stops).
//! * Start: from the actuator's measured state (history 1 on State): at rest, or, when a
//!   restarted planner finds the arm moving, a jerk-limited stop from its measured q and
//!   q̇ (the program is not run); mirroring it when the actuator is in its safe state.
//! * Motion: the config's program (if any), then run-time [`MotionCommand`]s: Move
//!   (joint or Cartesian target, soft/cubic/quintic/LSPB), Stop (shortest jerk-limited
//!   stop), EStop (the same at the e-stop limits, then refuse motion until Reset), Reset.
//!   A Reset during the e-stop's brake lets the brake finish: the e-stop lifts once the
//!   arm is at rest, so the setpoint never steps.
//!   Every command is validated field by field; a refused one is counted and never moves
//!   the arm. A new motion is planned from the current setpoint state (q, q̇, q̈), so the
//!   stream never jumps. A Move, Stop or EStop abandons the rest of the program.
//! * Safety: while the actuator reports its safe state, the setpoint follows the
//!   measured state (flag HOLD_FOR_SAFE_STATE); after the Reset, as soon as the
//!   actuator reports that it has left its safe state (it takes the same Reset; with
//!   `auto_resume`, whenever it does), the arm is brought to rest from the measured
//!   state with a jerk-limited stop. Stale measured state (free-running,
//!   older than `stale_ms`) triggers the same stop.
//! * Time: a setpoint's logical time is its tick number × period: one period per
//!   published setpoint, so a late or skipped tick delays the motion rather than making
//!   it jump.
//!
//! * Teleop: `[teleop] enabled` or a Teleop command (at rest) hands the setpoint to the
//!   master device (module [`teleop`]); Stop or EStop leave it with a jerk-limited stop.
//!
//! The logic lives in [`PlannerCore`] (no IPC); the service's stage (its ports, clock
//! and wake-up) in `stage.rs`.

pub mod config;
pub mod program;
mod stage;
pub mod teleop;

pub use stage::run;

use microrobot_messages::{
    Activity as ReportedActivity, CommandKind, Header, JointSetpoint, JointState as BusState,
    LifecycleState, MAX_JOINTS, MasterPose, MotionCommand, ProfileKind, ProgramEnd, ProgramState,
    RefusalQuantity, RefusalReason, TargetSpace, setpoint_flags, state_flags,
};
use microrobot_model::ik::{IkOptions, IkTarget};
use microrobot_model::{ModelData, Robot};
use microrobot_runtime::BadConfig;
use microrobot_runtime::config::{OwnedSection as _, PipelineConfig, ms_to_ns};

pub use config::TeleopConfig;
use microrobot_runtime::validate::{Refusal, SeqTracker, check_fresh, check_state};
use microrobot_trajectory::{
    Generator, JointVector, KinematicLimits, MotionRequest, MotionState, Profile, Sample, Status,
    Trajectory, TrajectoryError, stop_trajectory,
};

use crate::program::ProgramRunner;

/// Why a motion command was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    #[error("unknown command kind {0}")]
    UnknownKind(u32),
    #[error("unknown profile {0}")]
    UnknownProfile(u32),
    #[error("unknown target space {0}")]
    UnknownSpace(u32),
    #[error("target has {got} joints, the robot has {want}")]
    WrongDof { got: u32, want: usize },
    #[error("{field} is not finite")]
    NonFinite { field: &'static str },
    #[error("target joint {joint} = {value} is outside [{min}, {max}]")]
    OutOfLimits {
        joint: usize,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error(
        "duration_s = {0} is not valid for this profile (> 0 s and <= 3600 s; soft: 0 = time-optimal)"
    )]
    BadDuration(f64),
    #[error("limit_scale = {0} must be in [0.001, 1] (0: the config's default)")]
    BadLimitScale(f64),
    #[error("the command is stale or from the future (stamp {age_ms:.1} ms old)")]
    Stale { age_ms: f64 },
    #[error(
        "motion is refused during an e-stop; send reset first (a reset sent while braking takes effect at rest)"
    )]
    EStopActive,
    #[error("motion is refused while the actuator is in its safe state; send reset first")]
    SafeStateActive,
    #[error("no inverse-kinematics solution for the Cartesian target (residual {0:.3e} m)")]
    Unreachable(f64),
    #[error("the quaternion is not unit length")]
    BadQuaternion,
    #[error("cannot plan: {0}")]
    Plan(String),
    #[error("no trajectory within the limits: {0}")]
    Limits(TrajectoryError),
    #[error("the measured state is not known yet")]
    NotStarted,
    #[error("teleop is not available: {0}")]
    TeleopUnavailable(String),
    #[error("teleop is entered at rest only; stop the running motion first")]
    TeleopNotAtRest,
}

/// The limit a refused command broke: joint (index), quantity, value and range (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefusalDetail {
    pub joint: Option<usize>,
    pub quantity: RefusalQuantity,
    pub value: f64,
    pub min: f64,
    pub max: f64,
}

/// What a trajectory field name (`start.qdd`, `limits.velocity`, …) is a limit on.
fn quantity_of(field: &str) -> RefusalQuantity {
    if field.ends_with(".qdd") || field.ends_with("acceleration") {
        RefusalQuantity::Acceleration
    } else if field.ends_with(".qd") || field.ends_with("velocity") {
        RefusalQuantity::Velocity
    } else if field.ends_with("jerk") {
        RefusalQuantity::Jerk
    } else if field.ends_with(".q") || field.contains("position") {
        RefusalQuantity::Position
    } else {
        RefusalQuantity::None
    }
}

impl CommandError {
    /// The joint, quantity, value and range behind the refusal, where it has them (what
    /// `ServiceStatus::refusal_*` carries, so `send` can say it in the user's units).
    pub fn detail(&self) -> Option<RefusalDetail> {
        let inf = f64::INFINITY;
        match *self {
            Self::OutOfLimits {
                joint,
                value,
                min,
                max,
            } => Some(RefusalDetail {
                joint: Some(joint),
                quantity: RefusalQuantity::Position,
                value,
                min,
                max,
            }),
            Self::BadDuration(d) => Some(RefusalDetail {
                joint: None,
                quantity: RefusalQuantity::Duration,
                value: d,
                min: 0.0,
                max: 3600.0,
            }),
            Self::Limits(TrajectoryError::OutOfRange {
                joint,
                field,
                value,
                min,
                max,
            }) => Some(RefusalDetail {
                joint: Some(joint),
                quantity: quantity_of(field),
                value,
                min,
                max,
            }),
            Self::Limits(TrajectoryError::PositionOverrun {
                joint,
                field,
                reached,
                limit,
            }) => Some(RefusalDetail {
                joint: Some(joint),
                quantity: RefusalQuantity::Position,
                value: reached,
                min: if field.ends_with("min") { limit } else { -inf },
                max: if field.ends_with("min") { inf } else { limit },
            }),
            Self::Limits(TrajectoryError::NotPositive {
                joint,
                field,
                value,
            }) => Some(RefusalDetail {
                joint: Some(joint),
                quantity: quantity_of(field),
                value,
                min: 0.0,
                max: inf,
            }),
            _ => None,
        }
    }

    /// The wire code reported in `ServiceStatus::last_command_refusal`.
    pub fn reason(&self) -> RefusalReason {
        match self {
            Self::UnknownKind(_) => RefusalReason::UnknownKind,
            Self::UnknownProfile(_) => RefusalReason::UnknownProfile,
            Self::UnknownSpace(_) => RefusalReason::UnknownSpace,
            Self::WrongDof { .. } => RefusalReason::WrongDof,
            Self::NonFinite { .. } => RefusalReason::NonFinite,
            Self::OutOfLimits { .. } => RefusalReason::OutOfLimits,
            Self::BadDuration(_) => RefusalReason::BadDuration,
            Self::BadLimitScale(_) => RefusalReason::BadLimitScale,
            Self::Stale { .. } => RefusalReason::Stale,
            Self::EStopActive => RefusalReason::EStopActive,
            Self::SafeStateActive => RefusalReason::SafeStateActive,
            Self::Unreachable(_) => RefusalReason::Unreachable,
            Self::BadQuaternion => RefusalReason::BadQuaternion,
            Self::Plan(_) | Self::Limits(_) => RefusalReason::CannotPlan,
            Self::NotStarted => RefusalReason::NotStarted,
            Self::TeleopUnavailable(_) => RefusalReason::TeleopUnavailable,
            Self::TeleopNotAtRest => RefusalReason::TeleopNotAtRest,
        }
    }
}

/// The smallest `MotionCommand::limit_scale` accepted (0 aside, which means the
/// config's); the config's scales have the same floor.
pub use microrobot_runtime::config::MIN_LIMIT_SCALE;

/// What the planner is doing, as a plain label ([`PlannerCore::mode`]); the state
/// itself, with what each activity needs, is the private `Activity` enum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Holding a constant position.
    Hold,
    /// Executing a move (program segment or command).
    Moving,
    /// Braking for a Stop (or stale state).
    Stopping,
    /// Braking for / holding after an e-stop; motion refused until Reset.
    EStop,
    /// The actuator is in its safe state: following the measured state.
    SafeHold,
    /// The master device drives the arm.
    Teleop,
}

/// The planner's state machine: what it is doing, with the motion that does it. Every
/// transition replaces the whole activity, so no flag can disagree with another.
///
/// `AwaitingState` → (first measured state) `Program` | `Hold` | `Stopping` (the arm was
/// moving) | `SafeHold` (the actuator is latched) | `Teleop` (`[teleop] enabled`);
/// `Program`, `Move`, `Stopping` → `Hold` at their end; any → `Stopping` (Stop, stale
/// state), `EStop` (EStop), `SafeHold` (the actuator reports its safe state);
/// `EStop` → `Hold` on Reset at rest; `SafeHold` → `Stopping` once reset and the
/// actuator has left its safe state; `Hold` → `Move` | `Teleop` on command.
#[derive(Debug, Clone, Copy)]
enum Activity {
    /// No measured state yet: nothing to plan from.
    AwaitingState,
    /// Holding a constant position, at rest.
    Hold,
    /// The configured program drives the setpoint ([`PlannerCore`]'s `program`).
    Program,
    /// A commanded move.
    Move(Generator),
    /// Braking to rest: a Stop, a stale state, a start on a moving arm, a resume.
    Stopping(Generator),
    /// An e-stop: braking (`brake`), then holding; motion is refused until a Reset,
    /// which lifts it at rest (`reset_at_rest`: it came while still braking).
    EStop {
        brake: Option<Generator>,
        reset_at_rest: bool,
    },
    /// The actuator is in its safe state: the setpoint follows the measured state;
    /// `resume` once a Reset came (then, or with `auto_resume`, the planner resumes as
    /// soon as the actuator leaves its safe state).
    SafeHold { resume: bool },
    /// The master device drives the arm.
    Teleop,
}

impl Activity {
    /// The motion being run by a generator, if any (the program runs its own).
    fn generator(&mut self) -> Option<&mut Generator> {
        match self {
            Self::Move(g) | Self::Stopping(g) => Some(g),
            Self::EStop { brake, .. } => brake.as_mut(),
            _ => None,
        }
    }

    fn has_motion(&self) -> bool {
        matches!(
            self,
            Self::Move(_) | Self::Stopping(_) | Self::EStop { brake: Some(_), .. }
        )
    }
}

/// Cumulative counters of the planner.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counters {
    pub ticks: u64,
    pub commands_accepted: u64,
    pub commands_refused: u64,
    pub states_refused: u64,
    pub stale_cycles: u64,
    pub estops: u64,
}

/// Measured speed (rad/s or m/s) below which a (re)starting planner takes the arm as
/// at rest (the actuator's own rest threshold; sensor noise stays below it).
const START_REST_QD: f64 = 1e-3;

/// The planner's logic, independent of IPC and clocks.
pub struct PlannerCore {
    robot: Robot,
    data: ModelData,
    dof: usize,
    period_s: f64,
    lockstep: bool,
    stale_ns: u64,
    command_max_age_ns: u64,
    limits: KinematicLimits,
    full_limits: KinematicLimits,
    estop_limits: KinematicLimits,
    current: Sample,
    activity: Activity,
    program: Option<ProgramRunner>,
    program_done: bool,
    /// Where the configured program stands, and why it ended early (for the status).
    program_state: ProgramState,
    program_end: ProgramEnd,
    tick: u64,
    state_seq: SeqTracker,
    last_state: Option<BusState>,
    /// Counters for the status.
    pub counters: Counters,
    /// Last command error, for logging by the caller.
    pub last_error: Option<CommandError>,
    /// Why the last refused measured state was refused.
    pub last_state_refusal: Option<Refusal>,
    estop_at_ns: Option<u64>,
    /// `watchdog.auto_resume`: resume without a Reset when the actuator does.
    auto_resume: bool,
    /// Time from the last e-stop command's receipt to its first braking setpoint (ns).
    pub last_estop_latency_ns: Option<u64>,
    /// The largest such time so far (ns).
    pub max_estop_latency_ns: u64,
    teleop: teleop::TeleopMode,
    /// `[teleop] enabled`: start in teleop.
    teleop_at_start: bool,
    /// The measured state was stale at the last check (teleop holds meanwhile).
    state_stale: bool,
}

/// The limits the planner plans its program within: the robot's, scaled by
/// `planner.limit_scale` (a program's own `[limits]` replace the rates).
pub fn program_limits(robot: &Robot, cfg: &PipelineConfig) -> KinematicLimits {
    scaled(robot, cfg.planner.limit_scale)
}

fn scaled(robot: &Robot, scale: f64) -> KinematicLimits {
    let mut l = KinematicLimits::uniform(1.0, 1.0, 1.0, 0.0, 0.0);
    for (i, j) in robot.joints().iter().enumerate() {
        l.velocity[i] = j.limits.velocity * scale;
        l.acceleration[i] = j.limits.acceleration * scale;
        l.jerk[i] = j.limits.jerk * scale;
        l.position_min[i] = j.limits.min;
        l.position_max[i] = j.limits.max;
    }
    l
}

impl PlannerCore {
    /// A planner for `robot` with the settings of `cfg` and an optional program.
    pub fn new(robot: &Robot, cfg: &PipelineConfig, program: Option<ProgramRunner>) -> Self {
        Self {
            data: ModelData::new(robot),
            dof: robot.dof(),
            robot: robot.clone(),
            period_s: 1.0 / cfg.rate_hz,
            lockstep: cfg.lockstep,
            stale_ns: cfg.watchdog.stale_ns(),
            command_max_age_ns: ms_to_ns(cfg.planner.command_max_age_ms),
            limits: scaled(robot, cfg.planner.limit_scale),
            full_limits: scaled(robot, 1.0),
            estop_limits: scaled(robot, cfg.planner.estop_limit_scale),
            current: Sample::default(),
            activity: Activity::AwaitingState,
            program_done: program.is_none(),
            program_state: if program.is_some() {
                ProgramState::Pending
            } else {
                ProgramState::None
            },
            program_end: ProgramEnd::None,
            program,
            tick: 0,
            state_seq: SeqTracker::new(cfg.watchdog.stale_ns()),
            last_state: None,
            counters: Counters::default(),
            last_error: None,
            last_state_refusal: None,
            estop_at_ns: None,
            auto_resume: cfg.watchdog.auto_resume,
            last_estop_latency_ns: None,
            max_estop_latency_ns: 0,
            teleop: teleop::TeleopMode::new(robot, cfg, &scaled(robot, cfg.planner.limit_scale)),
            teleop_at_start: TeleopConfig::from_pipeline(cfg).is_ok_and(|t| t.enabled),
            state_stale: false,
        }
    }

    /// Teleop mode (its counters and latency histogram).
    pub fn teleop(&self) -> &teleop::TeleopMode {
        &self.teleop
    }

    /// Takes a master-device sample from `publisher` received at `now_ns` (used in
    /// teleop mode only; one device at a time, see [`teleop::TeleopMode::on_master`]).
    pub fn on_master(&mut self, m: &MasterPose, publisher: u128, now_ns: u64) -> bool {
        self.teleop.on_master(m, publisher, now_ns)
    }

    fn enter_teleop(&mut self) -> Result<Activity, CommandError> {
        self.teleop
            .enter(&self.current)
            .map_err(CommandError::TeleopUnavailable)?;
        self.program_done = false;
        tracing::info!("planner: teleop mode: the master device drives the arm");
        Ok(Activity::Teleop)
    }

    /// Current mode (before the first measured state: `Hold`).
    pub fn mode(&self) -> Mode {
        match self.activity {
            Activity::AwaitingState | Activity::Hold => Mode::Hold,
            Activity::Program | Activity::Move(_) => Mode::Moving,
            Activity::Stopping(_) => Mode::Stopping,
            Activity::EStop { .. } => Mode::EStop,
            Activity::SafeHold { .. } => Mode::SafeHold,
            Activity::Teleop => Mode::Teleop,
        }
    }

    /// Whether the program (if any) has finished or was abandoned, and the arm is at rest.
    pub fn program_done(&self) -> bool {
        self.program_done
    }

    /// What the planner is doing, as the status reports it.
    pub fn activity(&self) -> ReportedActivity {
        match self.activity {
            Activity::AwaitingState => ReportedActivity::Starting,
            Activity::Hold => ReportedActivity::Hold,
            Activity::Program => ReportedActivity::Program,
            Activity::Move(_) => ReportedActivity::Move,
            Activity::Stopping(_) => ReportedActivity::Stopping,
            Activity::EStop { .. } => ReportedActivity::EStop,
            Activity::SafeHold { .. } => ReportedActivity::SafeHold,
            Activity::Teleop => ReportedActivity::Teleop,
        }
    }

    /// Where the configured program stands: pending, running, finished, abandoned or
    /// not run, and why it ended early ([`ProgramEnd::None`] otherwise).
    pub fn program_outcome(&self) -> (ProgramState, ProgramEnd) {
        (self.program_state, self.program_end)
    }

    /// The program will not run (or run on): `state` with `why`, logged once.
    fn end_program(&mut self, state: ProgramState, why: ProgramEnd) {
        if self.program.take().is_some() {
            self.program_state = state;
            self.program_end = why;
            let verb = if state == ProgramState::NotRun {
                "not run"
            } else {
                "abandoned"
            };
            tracing::warn!("planner: program {verb}: {}", why.describe());
        }
    }

    /// Logical time of the last setpoint (s).
    pub fn motion_time_s(&self) -> f64 {
        self.tick as f64 * self.period_s
    }

    /// Whether the first measured state has been seen.
    pub fn started(&self) -> bool {
        !matches!(self.activity, Activity::AwaitingState)
    }

    /// Sequence gaps seen on the state stream.
    pub fn lost_messages(&self) -> u64 {
        self.state_seq.lost
    }

    /// The current setpoint state.
    pub fn current(&self) -> &Sample {
        &self.current
    }

    /// Validates a measured state (from `publisher`, received at `now_ns`); the first
    /// one sets the start position (at rest). Returns whether it was accepted.
    pub fn accept_state(&mut self, s: &BusState, publisher: u128, now_ns: u64) -> bool {
        self.accept_state_from(s, publisher, now_ns, || true)
    }

    /// [`Self::accept_state`], where a state that would take the stream over (its owner
    /// silent for `stale_ms`) is taken only if `from_pipeline()` says the pipeline's
    /// supervisor started its process ([`microrobot_runtime::provenance`]); another's is
    /// refused as an outsider's, so the planner plans only from its own actuator's
    /// measurements.
    pub fn accept_state_from(
        &mut self,
        s: &BusState,
        publisher: u128,
        now_ns: u64,
        from_pipeline: impl FnOnce() -> bool,
    ) -> bool {
        if let Err(e) = check_state(s, self.dof).and_then(|()| {
            self.state_seq
                .accept_from(publisher, s.header.seq, now_ns, from_pipeline)
        }) {
            self.counters.states_refused += 1;
            self.last_state_refusal = Some(e);
            return false;
        }
        self.last_state = Some(*s);
        match self.activity {
            Activity::AwaitingState => self.activity = self.start(s),
            Activity::Stopping(_) if self.counters.ticks == 0 => {
                // Started on a moving arm and not ticked yet: stop from the newest
                // measured state (the actuator's own hold changes it meanwhile).
                if let Some(m) = self.measured_sample() {
                    let prev = self.current;
                    self.current = Sample {
                        q: m.q,
                        qd: m.qd,
                        ..Default::default()
                    };
                    match self.brake(false) {
                        Ok(g) => self.activity = Activity::Stopping(g),
                        Err(_) => self.current = prev,
                    }
                }
            }
            _ => {}
        }
        true
    }

    /// The first measured state `s` (already taken as `last_state`): where and how the
    /// planner starts. From the measured state, velocity included: a restarted planner
    /// can find the arm still moving (held or damped by the actuator), and a setpoint
    /// at rest there would be a velocity jump.
    fn start(&mut self, s: &BusState) -> Activity {
        let Some(m) = self.measured_sample() else {
            return Activity::AwaitingState;
        };
        // At rest below START_REST_QD (sensor noise): start exactly at rest.
        let moving = (0..self.dof).any(|i| m.qd[i].abs() > START_REST_QD);
        self.current = Sample {
            q: m.q,
            qd: if moving { m.qd } else { JointVector::zeros() },
            ..Default::default()
        };
        let safe =
            s.flags & state_flags::SAFE_STATE != 0 || s.lifecycle == LifecycleState::Fault as u32;
        if safe {
            // The actuator is latched: mirror the measured arm from the first tick
            // (as `check_state` would from the next one).
            self.end_program(ProgramState::NotRun, ProgramEnd::SafeState);
            Activity::SafeHold { resume: false }
        } else if moving {
            // Bring the arm to rest from where it is (jerk-limited, bumpless).
            self.end_program(ProgramState::NotRun, ProgramEnd::MovingAtStart);
            match self.brake(false) {
                Ok(g) => Activity::Stopping(g),
                Err(_) => {
                    self.current.qd = JointVector::zeros();
                    Activity::Hold
                }
            }
        } else if self.teleop_at_start {
            self.end_program(ProgramState::NotRun, ProgramEnd::TeleopAtStart);
            self.enter_teleop().unwrap_or_else(|e| {
                tracing::error!("planner: cannot start in teleop mode: {e}");
                Activity::Hold
            })
        } else {
            self.start_program()
        }
    }

    fn measured_sample(&self) -> Option<Sample> {
        let s = self.last_state?;
        let mut out = Sample::default();
        for i in 0..self.dof {
            let lim = &self.robot.joints()[i].limits;
            out.q[i] = lim.clamp(s.q[i]);
            out.qd[i] = s.qd[i].clamp(-lim.velocity, lim.velocity);
        }
        Some(out)
    }

    fn start_program(&mut self) -> Activity {
        let Some(p) = self.program.as_mut() else {
            return Activity::Hold;
        };
        match p.plan(&self.robot, &self.current.state(), &self.limits) {
            Ok(()) => {
                tracing::info!(
                    "planner: program `{}` planned, {:.3} s",
                    p.name(),
                    p.duration()
                );
                self.program_state = ProgramState::Running;
                Activity::Program
            }
            Err(e) => {
                tracing::error!(
                    "planner: program cannot be planned from the measured state, program not run: {e}"
                );
                self.program = None;
                self.program_state = ProgramState::NotRun;
                self.program_end = ProgramEnd::CannotPlan;
                Activity::Hold
            }
        }
    }

    fn abandon_program(&mut self, why: ProgramEnd) {
        self.end_program(ProgramState::Abandoned, why);
    }

    /// The shortest jerk-limited stop from the current setpoint state, within the
    /// robot's limits or (`estop`) the e-stop's.
    ///
    /// The stop stays within every joint's position range: a joint whose own stop would
    /// leave it (the setpoint following a measured arm that moves towards a limit, e.g.
    /// one that sagged while its drives were off for a reset) stops at once where it is
    /// instead. A setpoint outside the range would be refused by the dynamics, leaving
    /// the actuator without torque commands.
    fn brake(&self, estop: bool) -> Result<Generator, CommandError> {
        let lim = if estop {
            self.estop_limits
        } else {
            self.full_limits
        };
        let mut start = self.current.state();
        let t = stop_trajectory(self.dof, &start, &lim).map_err(CommandError::Limits)?;
        let leaving = self.leaving_range(&t);
        if !leaving.iter().any(|&l| l) {
            return Ok(Generator::new(t));
        }
        for (i, j) in self.robot.joints().iter().enumerate().take(self.dof) {
            if leaving[i] {
                start.q[i] = j.limits.clamp(start.q[i]);
                start.qd[i] = 0.0;
                start.qdd[i] = 0.0;
            }
        }
        let t = stop_trajectory(self.dof, &start, &lim).map_err(CommandError::Limits)?;
        Ok(Generator::new(t))
    }

    /// Which joints of the stop `t` leave their position range, checked at
    /// [`STOP_CHECKS`] + 1 instants from its start to its end (once per stop, not per
    /// cycle).
    fn leaving_range(&self, t: &Trajectory) -> [bool; MAX_JOINTS] {
        let mut out = [false; MAX_JOINTS];
        let mut at = Sample::default();
        let d = t.duration();
        for k in 0..=STOP_CHECKS {
            t.sample_into(d * k as f64 / STOP_CHECKS as f64, &mut at);
            for (i, j) in self.robot.joints().iter().enumerate().take(self.dof) {
                out[i] |= !j.limits.contains(at.q[i]);
            }
        }
        out
    }

    /// Validates and executes a motion command received at `now_ns`.
    pub fn on_command(&mut self, c: &MotionCommand, now_ns: u64) -> Result<(), CommandError> {
        let r = self.command(c, now_ns);
        match &r {
            Ok(()) => self.counters.commands_accepted += 1,
            Err(e) => {
                self.counters.commands_refused += 1;
                self.last_error = Some(e.clone());
            }
        }
        r
    }

    fn command(&mut self, c: &MotionCommand, now_ns: u64) -> Result<(), CommandError> {
        let kind = CommandKind::from_wire(c.kind).ok_or(CommandError::UnknownKind(c.kind))?;
        if c.stamp_ns != 0
            && (c.stamp_ns > now_ns.saturating_add(1_000_000_000)
                || now_ns.saturating_sub(c.stamp_ns) > self.command_max_age_ns)
        {
            return Err(CommandError::Stale {
                age_ms: (now_ns as f64 - c.stamp_ns as f64) / 1e6,
            });
        }
        if !self.started() {
            return Err(CommandError::NotStarted);
        }
        match kind {
            CommandKind::Reset => {
                self.activity = match self.activity {
                    // Still braking: cutting the brake short would step the setpoint
                    // velocity and acceleration to zero. The brake runs to rest and
                    // `tick` lifts the e-stop there.
                    Activity::EStop { brake: Some(g), .. } => Activity::EStop {
                        brake: Some(g),
                        reset_at_rest: true,
                    },
                    // At rest (the brake's end holds qd = qdd = jerk = 0 exactly).
                    Activity::EStop { brake: None, .. } => Activity::Hold,
                    // Resume once the actuator has left its safe state (it takes the
                    // same reset): see `check_state`.
                    Activity::SafeHold { .. } => Activity::SafeHold { resume: true },
                    other => other,
                };
                Ok(())
            }
            CommandKind::EStop => {
                self.counters.estops += 1;
                self.estop_at_ns = Some(now_ns);
                self.abandon_program(ProgramEnd::Command);
                if let Activity::SafeHold { .. } = self.activity {
                    // The actuator already holds; stay with it, but remember the e-stop.
                    return Ok(());
                }
                self.activity = Activity::EStop {
                    brake: Some(self.brake(true)?),
                    reset_at_rest: false,
                };
                Ok(())
            }
            CommandKind::Stop => {
                self.check_motion_allowed()?;
                self.abandon_program(ProgramEnd::Command);
                self.activity = Activity::Stopping(self.brake(false)?);
                Ok(())
            }
            CommandKind::Teleop => {
                self.check_motion_allowed()?;
                match self.activity {
                    Activity::Teleop => Ok(()),
                    Activity::Program | Activity::Move(_) | Activity::Stopping(_) => {
                        Err(CommandError::TeleopNotAtRest)
                    }
                    _ => {
                        self.activity = self.enter_teleop()?;
                        Ok(())
                    }
                }
            }
            CommandKind::Move => {
                self.check_motion_allowed()?;
                let t = self.plan_move(c)?;
                self.abandon_program(ProgramEnd::Command);
                self.activity = Activity::Move(Generator::new(t));
                self.program_done = false;
                Ok(())
            }
        }
    }

    fn check_motion_allowed(&self) -> Result<(), CommandError> {
        match self.activity {
            Activity::EStop { .. } => Err(CommandError::EStopActive),
            Activity::SafeHold { .. } => Err(CommandError::SafeStateActive),
            _ => Ok(()),
        }
    }

    fn plan_move(&mut self, c: &MotionCommand) -> Result<Trajectory, CommandError> {
        let profile_kind =
            ProfileKind::from_wire(c.profile).ok_or(CommandError::UnknownProfile(c.profile))?;
        let space = TargetSpace::from_wire(c.space).ok_or(CommandError::UnknownSpace(c.space))?;
        if !c.duration_s.is_finite() {
            return Err(CommandError::NonFinite {
                field: "duration_s",
            });
        }
        if !c.limit_scale.is_finite() {
            return Err(CommandError::NonFinite {
                field: "limit_scale",
            });
        }
        if c.limit_scale != 0.0 && !(MIN_LIMIT_SCALE..=1.0).contains(&c.limit_scale) {
            return Err(CommandError::BadLimitScale(c.limit_scale));
        }
        let d = c.duration_s;
        let fixed = profile_kind != ProfileKind::Soft;
        if !(0.0..=3600.0).contains(&d) || (fixed && d <= 0.0) {
            return Err(CommandError::BadDuration(d));
        }
        let mut target = JointVector::zeros();
        match space {
            TargetSpace::Joint => {
                if c.dof as usize != self.dof {
                    return Err(CommandError::WrongDof {
                        got: c.dof,
                        want: self.dof,
                    });
                }
                for i in 0..self.dof {
                    let v = c.target[i];
                    if !v.is_finite() {
                        return Err(CommandError::NonFinite { field: "target" });
                    }
                    let l = &self.robot.joints()[i].limits;
                    if !l.contains(v) {
                        return Err(CommandError::OutOfLimits {
                            joint: i,
                            value: v,
                            min: l.min,
                            max: l.max,
                        });
                    }
                    target[i] = v;
                }
            }
            TargetSpace::Cartesian => {
                let t = &c.target;
                if !t[..7].iter().all(|v| v.is_finite()) {
                    return Err(CommandError::NonFinite { field: "target" });
                }
                let qn = (t[3] * t[3] + t[4] * t[4] + t[5] * t[5] + t[6] * t[6]).sqrt();
                if (qn - 1.0).abs() > 1e-3 {
                    return Err(CommandError::BadQuaternion);
                }
                let rot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    t[3], t[4], t[5], t[6],
                ));
                let iso = nalgebra::Isometry3::from_parts(
                    nalgebra::Translation3::new(t[0], t[1], t[2]),
                    rot,
                );
                let sol = microrobot_model::ik::solve(
                    &self.robot,
                    &mut self.data,
                    &IkTarget::Pose(iso),
                    &self.current.q,
                    &IkOptions {
                        position_tolerance_m: 1e-7,
                        orientation_tolerance_rad: 1e-6,
                        ..IkOptions::default()
                    },
                )
                .map_err(|e| CommandError::Plan(e.to_string()))?;
                if !sol.converged || sol.position_error_m > 1e-5 || sol.orientation_error_rad > 1e-4
                {
                    return Err(CommandError::Unreachable(sol.position_error_m));
                }
                target = sol.q;
            }
        }
        let mut limits = if c.limit_scale == 0.0 {
            self.limits
        } else {
            scaled(&self.robot, c.limit_scale)
        };
        limits.position_min = self.full_limits.position_min;
        limits.position_max = self.full_limits.position_max;
        let profile = match profile_kind {
            ProfileKind::Soft => Profile::Soft {
                min_duration: (d > 0.0).then_some(d),
            },
            ProfileKind::Cubic => Profile::Cubic { duration: d },
            ProfileKind::Quintic => Profile::Quintic { duration: d },
            ProfileKind::Lspb => Profile::Lspb {
                duration: d,
                cruise_velocity: None,
            },
        };
        let req = MotionRequest {
            dof: self.dof,
            start: self.current.state(),
            target: MotionState::at_rest(target),
            profile,
            limits,
        };
        let t = Trajectory::plan(&req).map_err(CommandError::Limits)?;
        // Fixed-duration profiles are not planned within the limits: refuse the ones
        // that would exceed the robot's own limits.
        t.check_limits(&self.full_limits, profile_kind == ProfileKind::Quintic)
            .map_err(CommandError::Limits)?;
        Ok(t)
    }

    /// Checks the measured state at `now_ns` (free-running): the actuator's safe state
    /// makes the setpoint follow the measured state; a stale state starts a stop.
    pub fn check_state(&mut self, now_ns: u64) {
        let Some(s) = self.last_state else {
            return;
        };
        let safe =
            s.flags & state_flags::SAFE_STATE != 0 || s.lifecycle == LifecycleState::Fault as u32;
        // Matched on the resume flag alone: the activity (with its motion, kilobytes)
        // is not copied every tick.
        let safe_hold = match self.activity {
            Activity::SafeHold { resume } => Some(resume),
            _ => None,
        };
        match (safe_hold, safe) {
            (Some(resume), false) if resume || self.auto_resume => {
                // The actuator follows commands again: bring the followed measured state
                // to rest, jerk-limited (bumpless from where the arm is).
                self.activity = match self.brake(false) {
                    Ok(g) => {
                        tracing::info!(
                            "planner: the actuator left its safe state; resuming from the measured state"
                        );
                        Activity::Stopping(g)
                    }
                    Err(_) => Activity::SafeHold { resume: false },
                };
                return;
            }
            (Some(_), true) => return,
            (None, true) => {
                tracing::warn!(
                    "planner: the actuator reports its safe state; following the measured state"
                );
                self.abandon_program(ProgramEnd::SafeState);
                self.activity = Activity::SafeHold { resume: false };
                return;
            }
            _ => {}
        }
        self.state_stale =
            !self.lockstep && check_fresh(s.header.stamp_ns, now_ns, self.stale_ns).is_err();
        if !self.state_stale {
            return;
        }
        // Teleop holds (the tool is brought to rest) until the state is fresh again.
        self.counters.stale_cycles += 1;
        if matches!(self.activity, Activity::Program | Activity::Move(_)) {
            tracing::warn!("planner: measured state is stale; stopping");
            self.abandon_program(ProgramEnd::StaleState);
            if let Ok(g) = self.brake(false) {
                self.activity = Activity::Stopping(g);
            }
        }
    }

    /// The running motion reached its end: hold exactly at rest there; the program is
    /// finished, a move or stop holds, an e-stop holds (lifted if a Reset came during
    /// its brake).
    fn finish_motion(&mut self) {
        self.current.qd = JointVector::zeros();
        self.current.qdd = JointVector::zeros();
        self.current.jerk = JointVector::zeros();
        self.activity = match self.activity {
            Activity::Program => {
                self.program = None;
                self.program_state = ProgramState::Finished;
                tracing::info!("planner: program finished");
                Activity::Hold
            }
            Activity::Move(_) | Activity::Stopping(_) => Activity::Hold,
            Activity::EStop {
                reset_at_rest: true,
                ..
            } => {
                tracing::info!("planner: e-stop brake finished; reset takes effect");
                Activity::Hold
            }
            Activity::EStop { .. } => Activity::EStop {
                brake: None,
                reset_at_rest: false,
            },
            other => other,
        };
    }

    /// One tick: advances the motion by one period and returns the setpoint (stamped
    /// `now_ns`).
    pub fn tick(&mut self, now_ns: u64) -> JointSetpoint {
        self.tick += 1;
        self.counters.ticks += 1;
        let mut flags = 0;
        match &mut self.activity {
            Activity::SafeHold { .. } => {
                if let Some(m) = self.measured_sample() {
                    self.current = m;
                }
                flags |= setpoint_flags::HOLD_FOR_SAFE_STATE;
            }
            Activity::Teleop => {
                if let Some((sample, bits)) = self.teleop.step(now_ns, self.state_stale) {
                    self.current = sample;
                    flags |= bits;
                    if (0..self.dof).any(|i| sample.qd[i] != 0.0 || sample.qdd[i] != 0.0) {
                        flags |= setpoint_flags::MOVING;
                    }
                }
            }
            activity => {
                // The sample goes straight into `current` (no 256-byte return value).
                let (dt, current) = (self.period_s, &mut self.current);
                let step = match activity {
                    Activity::Program => self
                        .program
                        .as_mut()
                        .and_then(|p| p.update_into(dt, current)),
                    a => a.generator().map(|g| g.update_into(dt, current)),
                };
                if step == Some(Status::Finished) {
                    self.finish_motion();
                }
                if step.is_some() {
                    flags |= setpoint_flags::MOVING;
                }
            }
        }
        match self.activity {
            Activity::Stopping(_) => flags |= setpoint_flags::STOPPING,
            Activity::EStop { brake: Some(_), .. } => {
                flags |= setpoint_flags::ESTOP | setpoint_flags::STOPPING;
            }
            Activity::EStop { brake: None, .. } => flags |= setpoint_flags::ESTOP,
            _ => {}
        }
        if self.program.is_none()
            && !self.activity.has_motion()
            && !matches!(self.activity, Activity::SafeHold { .. } | Activity::Teleop)
        {
            self.program_done = true;
        }
        if self.program_done {
            flags |= setpoint_flags::PROGRAM_DONE;
        }
        // An e-stop in the actuator's safe state brakes nothing (the arm already holds):
        // only a braking setpoint is timed.
        if let Some(t) = self.estop_at_ns.take()
            && matches!(self.activity, Activity::EStop { .. })
        {
            let l = now_ns.saturating_sub(t);
            self.last_estop_latency_ns = Some(l);
            self.max_estop_latency_ns = self.max_estop_latency_ns.max(l);
            tracing::info!(
                "planner: e-stop: first braking setpoint {:.1} µs after the command",
                l as f64 / 1e3
            );
        }
        let mut sp = JointSetpoint {
            header: Header {
                seq: self.tick,
                tick: self.tick,
                stamp_ns: now_ns,
                source_stamp_ns: now_ns,
            },
            dof: self.dof as u32,
            flags,
            ..Default::default()
        };
        for i in 0..self.dof.min(MAX_JOINTS) {
            sp.q[i] = self.current.q[i];
            sp.qd[i] = self.current.qd[i];
            sp.qdd[i] = self.current.qdd[i];
            sp.jerk[i] = self.current.jerk[i];
        }
        sp
    }
}

/// Instants of a stop checked against the joints' ranges, its start and end included
/// (the end is its extreme while each joint's velocity keeps its sign, the usual case).
const STOP_CHECKS: usize = 16;

/// Loads the robot file named by the config (a bad file is a config error).
pub fn load_robot(cfg: &PipelineConfig) -> anyhow::Result<Robot> {
    let robot = Robot::from_file(&cfg.robot).map_err(|e| BadConfig(format!("robot file: {e}")))?;
    if let Some(msg) = missing_limits_error(&robot) {
        return Err(BadConfig(format!("robot file {}: {msg}", cfg.robot.display())).into());
    }
    Ok(robot)
}

/// Why `robot` cannot be planned for: the rate limits its description lacks (a URDF
/// gives no acceleration or jerk limits), named by the overlay keys that would give them.
pub fn missing_limits_error(robot: &Robot) -> Option<String> {
    let missing = robot.missing_limits();
    (!missing.is_empty()).then(|| {
        format!(
            "the planner needs acceleration and jerk limits the robot description does not give; \
             add them to the robot's overlay file: {}",
            missing.join(", ")
        )
    })
}
