//! `microrobot driver-check -- <driver command>`: runs any actuator driver, in any
//! language, against a scripted dynamics (a hold law from the robot model) and checks
//! the driver contract of `messages/README.md` clause by clause.
//!
//! The driver is started as `microrobot run` starts it (placeholders `{instance}`,
//! `{config}`, `{rate_hz}`, `{run_dir}`, the same environment, its own process group),
//! on a private instance. The rig then plays the pipeline's part in this order:
//! ready status → initial state (subscribed late, as the planner is) → torques for 2 s
//! → torques paused between `stale_ms` and `fault_ms` (free-running) → torques paused
//! past `fault_ms` → reset → SIGTERM → (free-running) SIGKILL and a restart that must
//! resume where the killed driver stopped. Each clause reports pass/fail and what was
//! seen; any failure makes the exit code `JOB_FAILED`.
//!
//! The torques hold the arm where it started: `τ = h(q, q̇) + M(q)·(kp·(q₀ − q) − kd·q̇)`
//! with a 5 Hz critically damped loop, so a real arm on a real driver stays put.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::LogLevel;
use iceoryx2::service::ipc;
use microrobot_messages::{
    CommandKind, Header, JointState, LifecycleState, MAX_JOINTS, MotionCommand, ServiceKind,
    ServiceRole, ServiceStatus, TorqueCommand, monotonic_ns, open_event, open_publish_subscribe,
    state_flags, torque_flags,
};
use microrobot_model::{JointVector, ModelData, Robot, mass_matrix, nonlinear_effects};
use microrobot_runtime::exit_code;
use microrobot_runtime::{Outbox, PipelineConfig};
use serde::Serialize;

use crate::instance;
use crate::monitor::StatusMonitor;
use crate::process::{Launch, Service, describe};

/// Arguments of `microrobot driver-check`.
#[derive(Debug, Clone, clap::Args)]
pub struct DriverCheckArgs {
    /// Pipeline config: the robot, rate, watchdog and timeouts the driver is held to.
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config())]
    pub config: PathBuf,
    /// Check the lockstep contract (one state per torque) instead of free-running.
    #[arg(long)]
    pub lockstep: bool,
    /// For drives that quantise torque: the step of the torque they receive, in N·m
    /// (N for a prismatic joint), one for every joint or one per joint (`R1,R2,...`).
    /// The `torque applied` clause then passes a state whose `tau_applied` is within
    /// half a step of the torque it names; without it, within 1e-6.
    #[arg(
        long = "torque-resolution-nm",
        value_name = "R[,R2,...]",
        value_delimiter = ','
    )]
    pub torque_resolution_nm: Vec<f64>,
    /// Also write the clauses as JSON to this file.
    #[arg(long = "summary-json", visible_alias = "json", value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// The driver's command line, after `--` (placeholders as in `[actuator] command`).
    #[arg(last = true, required = true, value_name = "DRIVER COMMAND")]
    pub command: Vec<String>,
}

/// One clause of the contract and what the rig saw.
#[derive(Debug, Clone, Serialize)]
pub struct Clause {
    pub name: &'static str,
    pub pass: bool,
    pub seen: String,
}

/// The verdict: every clause, and whether all passed.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    pub driver: Vec<String>,
    pub lockstep: bool,
    /// The driver's output (every start of it during the check).
    pub driver_log: PathBuf,
    pub pass: bool,
    pub clauses: Vec<Clause>,
}

/// Natural frequency of the hold loop (rad/s): 5 Hz, critically damped.
const HOLD_OMEGA: f64 = 2.0 * std::f64::consts::PI * 5.0;

/// A torque the rig sent, to match states against.
#[derive(Debug, Clone, Copy)]
struct Sent {
    tick: u64,
    source_stamp_ns: u64,
    tau: [f64; MAX_JOINTS],
}

/// A state as received.
#[derive(Debug, Clone, Copy)]
struct Seen {
    state: JointState,
}

/// How often new states and statuses were found, and how often with their events: a
/// driver that notifies after each message wakes a listener about as often as the
/// polls find new messages (an event can land one poll after its message).
#[derive(Debug, Clone, Copy, Default)]
struct Notified {
    state_polls: u64,
    state_events: u64,
    status_polls: u64,
    status_events: u64,
}

/// Consumes a listener's pending events; whether there were any.
fn events(l: &Listener<ipc::Service>) -> bool {
    let mut any = false;
    let _ = l.try_wait(|_| any = true);
    any
}

/// The scripted pipeline around the driver.
struct Rig {
    robot: Robot,
    data: ModelData,
    dof: usize,
    period: Duration,
    lockstep: bool,
    monitor: StatusMonitor,
    torque: Outbox<TorqueCommand>,
    command: Outbox<MotionCommand>,
    state_sub: Option<Subscriber<ipc::Service, JointState, ()>>,
    /// The driver's `notify()` after its states and statuses.
    state_events: Listener<ipc::Service>,
    status_events: Listener<ipc::Service>,
    notified: Notified,
    instance: String,
    /// Every torque sent, `sent[seq - 1]`.
    sent: Vec<Sent>,
    /// Every state received, in order.
    states: Vec<Seen>,
    /// Every actuator status received, in order.
    statuses: Vec<ServiceStatus>,
    /// Where the hold law holds the arm.
    hold_q: JointVector,
    /// Per joint, the drives' torque step (`--torque-resolution-nm`), if they quantise.
    torque_resolution: Option<JointVector>,
    tick: u64,
    command_seq: u64,
}

impl Rig {
    fn open(cfg: &PipelineConfig, robot: Robot) -> anyhow::Result<Self> {
        let instance = cfg.instance.clone();
        let monitor = StatusMonitor::open(
            &instance,
            &format!("microrobot-driver-check.{instance}.{}", std::process::id()),
        )?;
        let node = monitor.node();
        let torque = Outbox::open(node, &instance, microrobot_messages::topic::TORQUE)?;
        let command = Outbox::open(node, &instance, microrobot_messages::topic::COMMAND)?;
        let listen = |kind: ServiceKind| -> anyhow::Result<Listener<ipc::Service>> {
            open_event(node, &instance, kind)?
                .listener_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("{kind:?} listener: {e:?}"))
        };
        let (state_events, status_events) =
            (listen(ServiceKind::State)?, listen(ServiceKind::Status)?);
        let data = ModelData::new(&robot);
        let dof = robot.dof();
        Ok(Self {
            robot,
            data,
            dof,
            period: Duration::from_nanos(cfg.period_ns()),
            lockstep: cfg.lockstep,
            monitor,
            torque,
            command,
            state_sub: None,
            state_events,
            status_events,
            notified: Notified::default(),
            instance,
            sent: Vec::new(),
            states: Vec::new(),
            statuses: Vec::new(),
            hold_q: JointVector::zeros(),
            torque_resolution: None,
            tick: 0,
            command_seq: 0,
        })
    }

    /// Subscribes to the driver's states, as the planner does after the driver is ready.
    fn subscribe_states(&mut self) -> anyhow::Result<()> {
        let svc = open_publish_subscribe::<JointState>(
            self.monitor.node(),
            &self.instance,
            ServiceKind::State,
        )?;
        self.state_sub = Some(
            svc.subscriber_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("state subscriber: {e:?}"))?,
        );
        Ok(())
    }

    /// Takes every waiting state and actuator status.
    fn pump(&mut self) -> anyhow::Result<()> {
        let (states, statuses) = (self.states.len(), self.statuses.len());
        if let Some(sub) = &self.state_sub {
            loop {
                match sub.receive() {
                    Ok(Some(s)) => self.states.push(Seen { state: *s }),
                    Ok(None) => break,
                    Err(e) => anyhow::bail!("state receive: {e:?}"),
                }
            }
        }
        for st in self.monitor.poll_all()? {
            if st.role == ServiceRole::Actuator as u32 {
                self.statuses.push(st);
            }
        }
        let n = &mut self.notified;
        n.state_polls += u64::from(self.states.len() > states);
        n.state_events += u64::from(events(&self.state_events));
        n.status_polls += u64::from(self.statuses.len() > statuses);
        n.status_events += u64::from(events(&self.status_events));
        Ok(())
    }

    fn last_state(&self) -> Option<&JointState> {
        self.states.last().map(|s| &s.state)
    }

    /// The hold law's torque for the newest state.
    fn hold_torque(&mut self) -> [f64; MAX_JOINTS] {
        let (q, qd) = match self.last_state() {
            Some(s) => (vec8(&s.q), vec8(&s.qd)),
            None => (self.hold_q, JointVector::zeros()),
        };
        let h = nonlinear_effects(&self.robot, &mut self.data, &q, &qd);
        let m = mass_matrix(&self.robot, &mut self.data, &q);
        let mut a = JointVector::zeros();
        for i in 0..self.dof {
            a[i] = HOLD_OMEGA * HOLD_OMEGA * (self.hold_q[i] - q[i]) - 2.0 * HOLD_OMEGA * qd[i];
        }
        let tau = h + m * a;
        let mut out = [0.0; MAX_JOINTS];
        for (i, o) in out.iter_mut().enumerate().take(self.dof) {
            let limit = self.robot.joints()[i].limits.effort;
            *o = tau[i].clamp(-limit, limit);
        }
        out
    }

    /// Publishes one torque command (the next tick).
    fn send_torque(&mut self) -> anyhow::Result<u64> {
        let tau = self.hold_torque();
        self.tick += 1;
        let seq = self.sent.len() as u64 + 1;
        let now = monotonic_ns();
        let mut q_desired = [0.0; MAX_JOINTS];
        q_desired[..self.dof].copy_from_slice(&self.hold_q.as_slice()[..self.dof]);
        let msg = TorqueCommand {
            header: Header {
                seq,
                tick: self.tick,
                stamp_ns: now,
                source_stamp_ns: now,
            },
            tau,
            q_desired,
            setpoint_seq: self.tick,
            state_seq: self.last_state().map_or(u64::MAX, |s| s.header.seq),
            dof: self.dof as u32,
            flags: torque_flags::FEEDBACK,
        };
        anyhow::ensure!(self.torque.send(msg), "cannot send a torque command");
        self.sent.push(Sent {
            tick: self.tick,
            source_stamp_ns: now,
            tau,
        });
        Ok(seq)
    }

    /// Sends a reset command on `command`.
    fn send_reset(&mut self) -> anyhow::Result<()> {
        self.command_seq += 1;
        let msg = MotionCommand {
            seq: self.command_seq,
            stamp_ns: monotonic_ns(),
            kind: CommandKind::Reset as u32,
            ..MotionCommand::default()
        };
        anyhow::ensure!(self.command.send(msg), "cannot send a reset command");
        Ok(())
    }

    /// Runs for `dur`: with `torques`, one torque per period (free-running) or one per
    /// state (lockstep: the next torque once the state for the last one arrived); the
    /// states and statuses are taken throughout. Returns the lockstep torques whose
    /// state did not come within 1 s.
    fn drive(&mut self, dur: Duration, torques: bool) -> anyhow::Result<u32> {
        let end = Instant::now() + dur;
        let mut next = Instant::now();
        let mut unanswered = 0;
        let mut waiting: Option<(u64, Instant)> = None;
        while Instant::now() < end {
            self.pump()?;
            if torques {
                if self.lockstep {
                    let answered = match waiting {
                        None => true,
                        Some((seq, since)) => {
                            let got = self.states.iter().rev().take(4).any(|s| {
                                s.state.torque_seq == seq && s.state.flags & state_flags::FINAL == 0
                            });
                            if !got && since.elapsed() > Duration::from_secs(1) {
                                unanswered += 1;
                            }
                            got || since.elapsed() > Duration::from_secs(1)
                        }
                    };
                    if answered {
                        let seq = self.send_torque()?;
                        waiting = Some((seq, Instant::now()));
                    }
                } else if Instant::now() >= next {
                    self.send_torque()?;
                    next += self.period;
                    if next < Instant::now() {
                        next = Instant::now() + self.period;
                    }
                }
            }
            std::thread::sleep(Duration::from_micros(50));
        }
        // Lockstep: the last torque's state is still owed.
        if let Some((seq, _)) = waiting {
            let answered = self.wait(Duration::from_secs(1), |r| {
                r.states
                    .iter()
                    .rev()
                    .take(4)
                    .any(|s| s.state.torque_seq == seq)
            })?;
            if !answered {
                unanswered += 1;
            }
        }
        self.pump()?;
        Ok(unanswered)
    }

    /// Polls until `done` holds for the newest data or `timeout` passes.
    fn wait(&mut self, timeout: Duration, done: impl FnMut(&Self) -> bool) -> anyhow::Result<bool> {
        crate::monitor::poll_until(self, timeout, Duration::from_millis(1), Self::pump, done)
    }
}

fn vec8(v: &[f64; MAX_JOINTS]) -> JointVector {
    JointVector::from_column_slice(v)
}

fn lifecycle_name(v: u32) -> String {
    match LifecycleState::from_wire(v) {
        Some(l) => format!("{l:?}").to_lowercase(),
        None => format!("unknown ({v})"),
    }
}

/// `microrobot driver-check`: prints the clause table; exit 0 only if every clause passed.
pub fn main(args: DriverCheckArgs) -> ExitCode {
    match check(&args) {
        Ok(verdict) => {
            print_table(&verdict);
            if let Some(path) = &args.json {
                let text = match serde_json::to_string_pretty(&verdict) {
                    Ok(t) => t,
                    Err(e) => {
                        eprintln!("error: cannot encode the verdict: {e}");
                        return ExitCode::from(exit_code::FAILURE);
                    }
                };
                if let Err(e) = std::fs::write(path, text) {
                    eprintln!("error: --summary-json {}: {e}", path.display());
                    return ExitCode::from(exit_code::FAILURE);
                }
            }
            if verdict.pass {
                println!("driver-check: PASS ({} clauses)", verdict.clauses.len());
                ExitCode::from(exit_code::OK)
            } else {
                let failed: Vec<&str> = verdict
                    .clauses
                    .iter()
                    .filter(|c| !c.pass)
                    .map(|c| c.name)
                    .collect();
                println!("driver-check: FAILED: {}", failed.join(", "));
                ExitCode::from(exit_code::JOB_FAILED)
            }
        }
        Err((code, e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(code)
        }
    }
}

fn print_table(v: &Verdict) {
    let width = v.clauses.iter().map(|c| c.name.len()).max().unwrap_or(6);
    println!(
        "driver-check of `{}` ({})",
        v.driver.join(" "),
        if v.lockstep {
            "lockstep"
        } else {
            "free-running"
        }
    );
    for c in &v.clauses {
        println!(
            "  {:<width$}  {}  {}",
            c.name,
            if c.pass { "pass" } else { "FAIL" },
            c.seen
        );
    }
    println!("  driver output: {}", v.driver_log.display());
}

type Fail = (u8, anyhow::Error);

fn bad_config(e: anyhow::Error) -> Fail {
    (exit_code::BAD_CONFIG, e)
}

fn failure(e: anyhow::Error) -> Fail {
    (exit_code::FAILURE, e)
}

/// Loads the config for the check: a private instance, lockstep as asked.
fn load_config(args: &DriverCheckArgs) -> anyhow::Result<PipelineConfig> {
    let mut cfg = microrobot_config::load(&args.config).map_err(anyhow::Error::new)?;
    cfg.instance = format!("drvcheck-{}", std::process::id());
    cfg.lockstep = args.lockstep;
    cfg.program = None;
    let origin = format!("{} (driver-check)", args.config.display());
    let base = args.config.parent().unwrap_or(Path::new("."));
    microrobot_config::from_toml_str(&cfg.to_toml_string(), &origin, base)
        .map_err(anyhow::Error::new)
}

/// The driver's launch, as `microrobot run` builds it (this process is its supervisor).
fn launch(
    args: &DriverCheckArgs,
    cfg: &PipelineConfig,
    resolved: &Path,
    run_dir: &Path,
    resume: Option<String>,
) -> Launch {
    let mut env = crate::run::service_env(cfg, resolved);
    if let Some(r) = resume {
        env.push((microrobot_actuator::resume::RESUME_ENV.to_string(), r));
    }
    Launch {
        role: "actuator",
        argv: crate::run::driver_argv(&args.command, cfg, resolved, run_dir),
        env,
        log: run_dir.join("driver.log"),
    }
}

/// Runs the whole check; `Err` only when the check itself could not run.
pub fn check(args: &DriverCheckArgs) -> Result<Verdict, Fail> {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Error);
    let cfg = load_config(args)
        .with_context(|| format!("bad config {}", args.config.display()))
        .map_err(bad_config)?;
    let robot = Robot::from_file(&cfg.robot)
        .map_err(|e| anyhow::anyhow!("bad config: robot {}: {e}", cfg.robot.display()))
        .map_err(bad_config)?;
    let torque_resolution = torque_resolution(&args.torque_resolution_nm, robot.dof())
        .map_err(|e| bad_config(anyhow::anyhow!("--torque-resolution-nm: {e}")))?;
    let _lock = instance::lock_instance(&cfg.instance).map_err(failure)?;
    instance::clean_leftovers(&cfg.instance);
    let run_dir = instance::run_dir(&cfg.instance).map_err(failure)?;
    let resolved = run_dir.join("pipeline.resolved.toml");
    instance::write_private(&resolved, cfg.to_toml_string().as_bytes()).map_err(failure)?;
    crate::driver_info::write(&cfg, &robot, &resolved).map_err(failure)?;

    let mut rig = Rig::open(&cfg, robot).map_err(failure)?;
    rig.torque_resolution = torque_resolution;
    let mut driver =
        Service::spawn(launch(args, &cfg, &resolved, &run_dir, None)).map_err(failure)?;
    let result = script(&mut rig, &mut driver, &cfg, args, &resolved, &run_dir);
    driver.kill_and_reap();
    let clauses = result.map_err(failure)?;
    Ok(Verdict {
        driver: args.command.clone(),
        lockstep: cfg.lockstep,
        driver_log: run_dir.join("driver.log"),
        pass: clauses.iter().all(|c| c.pass),
        clauses,
    })
}

/// `--torque-resolution-nm`: none, one step for every joint, or one per joint; each
/// finite and positive.
fn torque_resolution(r: &[f64], dof: usize) -> Result<Option<JointVector>, String> {
    if r.is_empty() {
        return Ok(None);
    }
    if r.len() != 1 && r.len() != dof {
        return Err(format!(
            "{} values for {dof} joints (give one, or one per joint)",
            r.len()
        ));
    }
    if let Some(bad) = r.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(format!("{bad} is not a positive step"));
    }
    let mut out = JointVector::zeros();
    for i in 0..dof {
        out[i] = if r.len() == 1 { r[0] } else { r[i] };
    }
    Ok(Some(out))
}

/// The script: each step appends its clauses; a step whose precondition failed ends it.
fn script(
    rig: &mut Rig,
    driver: &mut Service,
    cfg: &PipelineConfig,
    args: &DriverCheckArgs,
    resolved: &Path,
    run_dir: &Path,
) -> anyhow::Result<Vec<Clause>> {
    let mut out = Vec::new();
    let dof = rig.dof;
    let ready_timeout = Duration::from_secs_f64(cfg.supervisor.ready_timeout_ms / 1000.0);

    // 1. Ready: a status with role actuator and ready = 1.
    let ready = rig.wait(ready_timeout, |r| r.statuses.iter().any(|s| s.ready == 1))?;
    let exited = driver.poll_exit();
    out.push(Clause {
        name: "ready status",
        pass: ready,
        seen: if ready {
            "status role actuator, ready = 1".to_string()
        } else if let Some(e) = exited {
            format!("the driver exited before it was ready ({})", describe(e))
        } else {
            format!(
                "no ready status within {:.1} s",
                ready_timeout.as_secs_f64()
            )
        },
    });
    if !ready {
        return Ok(out);
    }

    // 2. Initial state, to a subscriber that joined after it was published.
    rig.subscribe_states()?;
    let state_timeout = Duration::from_secs_f64(cfg.planner.state_timeout_ms / 1000.0);
    let got = rig.wait(state_timeout, |r| !r.states.is_empty())?;
    let initial = rig.states.first().map(|s| s.state);
    out.push(match initial {
        None => Clause {
            name: "initial state",
            pass: false,
            seen: format!(
                "no state reached a late subscriber within {:.1} s (publish an initial state and call update_connections() every period until the first torque)",
                state_timeout.as_secs_f64()
            ),
        },
        Some(s) => {
            let mut bad = Vec::new();
            if s.torque_seq != u64::MAX {
                bad.push(format!("torque_seq {} (want u64::MAX)", s.torque_seq));
            }
            if s.dof as usize != dof {
                bad.push(format!("dof {} (the robot has {dof})", s.dof));
            }
            if s.lifecycle != LifecycleState::Inactive as u32 {
                bad.push(format!("lifecycle {} (want inactive)", lifecycle_name(s.lifecycle)));
            }
            if s.header.tick != 0 {
                bad.push(format!("header.tick {} (want 0: no torque applied yet)", s.header.tick));
            }
            for (i, j) in rig.robot.joints().iter().enumerate() {
                let q = s.q[i];
                if !q.is_finite() || !j.limits.contains(q) {
                    bad.push(format!("q[{i}] = {q} outside [{}, {}]", j.limits.min, j.limits.max));
                }
            }
            Clause {
                name: "initial state",
                pass: got && bad.is_empty(),
                seen: if bad.is_empty() {
                    format!("q = {:?}, torque_seq none, inactive", &s.q[..dof.min(s.dof as usize)])
                } else {
                    bad.join("; ")
                },
            }
        }
    });
    let Some(initial) = initial else {
        return Ok(out);
    };
    rig.hold_q = vec8(&initial.q);

    // 3. Torques for 2 s.
    let from_state = rig.states.len();
    let from_status = rig.statuses.len();
    let t0 = monotonic_ns();
    let unanswered = rig.drive(Duration::from_secs(2), true)?;
    let t1 = monotonic_ns();
    out.extend(check_torque_phase(rig, from_state, t0, t1, unanswered));
    out.push(check_status(rig, from_status, cfg));
    out.push(check_notify(&rig.notified));

    // 4. Torques paused past stale_ms, short of fault_ms (free-running only).
    if !rig.lockstep {
        let pause =
            Duration::from_secs_f64((cfg.watchdog.stale_ms + cfg.watchdog.fault_ms) / 2000.0);
        let from = rig.states.len();
        let stale0 = rig.statuses.last().map_or(0, |s| s.stale_cycles);
        rig.drive(pause, false)?;
        let during: Vec<u32> = rig.states[from..].iter().map(|s| s.state.flags).collect();
        let stale_seen = during.iter().any(|f| f & state_flags::COMMAND_STALE != 0);
        let latched = during.iter().any(|f| f & state_flags::SAFE_STATE != 0);
        rig.drive(Duration::from_millis(500), true)?;
        let stale1 = rig.statuses.last().map_or(0, |s| s.stale_cycles);
        let fresh_again = rig.states.last().is_some_and(|s| {
            s.state.flags & (state_flags::COMMAND_STALE | state_flags::SAFE_STATE) == 0
        });
        out.push(Clause {
            name: "stale torques",
            pass: stale_seen && !latched && stale1 > stale0 && fresh_again,
            seen: format!(
                "{} ms without torque: {} of {} states COMMAND_STALE, safe state {}, status stale_cycles {stale0} -> {stale1}, fresh again after torques: {fresh_again}",
                pause.as_millis(),
                during.iter().filter(|f| *f & state_flags::COMMAND_STALE != 0).count(),
                during.len(),
                if latched { "latched (too early)" } else { "not latched" },
            ),
        });
    }

    // 5. Torques paused past fault_ms: the safe state latches.
    let faults0 = rig.statuses.last().map_or(0, |s| s.faults);
    let pause = Duration::from_secs_f64(cfg.watchdog.fault_ms * 1.5 / 1000.0 + 0.2);
    rig.drive(pause, false)?;
    let latched = rig.wait(Duration::from_millis(500), |r| {
        r.states.last().is_some_and(|s| {
            s.state.flags & state_flags::SAFE_STATE != 0
                && s.state.lifecycle == LifecycleState::Fault as u32
        }) && r
            .statuses
            .last()
            .is_some_and(|s| s.lifecycle == LifecycleState::Fault as u32)
    })?;
    let faults1 = rig.statuses.last().map_or(0, |s| s.faults);
    out.push(Clause {
        name: "safe state",
        pass: latched && faults1 > faults0,
        seen: format!(
            "{} ms without torque: state flags {:#x}, state lifecycle {}, status lifecycle {}, faults {faults0} -> {faults1}",
            pause.as_millis(),
            rig.last_state().map_or(0, |s| s.flags),
            rig.last_state().map_or("none".into(), |s| lifecycle_name(s.lifecycle)),
            rig.statuses.last().map_or("none".into(), |s| lifecycle_name(s.lifecycle)),
        ),
    });

    // 6. Reset with fresh torques.
    rig.drive(Duration::from_millis(200), true)?;
    rig.send_reset()?;
    let mut reset_ok = false;
    let end = Instant::now() + Duration::from_secs(1);
    while Instant::now() < end {
        rig.drive(Duration::from_millis(20), true)?;
        if rig.states.last().is_some_and(|s| {
            s.state.flags & state_flags::SAFE_STATE == 0
                && s.state.lifecycle == LifecycleState::Active as u32
        }) {
            reset_ok = true;
            break;
        }
    }
    rig.drive(Duration::from_millis(300), true)?;
    let status_active = rig
        .statuses
        .last()
        .is_some_and(|s| s.lifecycle == LifecycleState::Active as u32);
    out.push(Clause {
        name: "reset",
        pass: reset_ok && status_active,
        seen: format!(
            "after a reset command with fresh torques: state flags {:#x}, lifecycle {}, status lifecycle {}",
            rig.last_state().map_or(0, |s| s.flags),
            rig.last_state().map_or("none".into(), |s| lifecycle_name(s.lifecycle)),
            rig.statuses.last().map_or("none".into(), |s| lifecycle_name(s.lifecycle)),
        ),
    });

    // 7. SIGTERM: final state, final status, exit 0 within stop_timeout_ms.
    let last_before = rig.states.len();
    let last_status = rig.statuses.len();
    driver.signal(libc::SIGTERM);
    let stop_timeout = Duration::from_secs_f64(cfg.supervisor.stop_timeout_ms / 1000.0);
    let end = Instant::now() + stop_timeout;
    let mut exit = None;
    while Instant::now() < end {
        rig.pump()?;
        if let Some(e) = driver.poll_exit() {
            exit = Some(e);
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    rig.pump()?;
    let final_state = rig.states[last_before..]
        .iter()
        .find(|s| s.state.flags & state_flags::FINAL != 0);
    let final_status = rig.statuses[last_status..]
        .iter()
        .any(|s| s.lifecycle == LifecycleState::Finalized as u32);
    let clean = exit.is_some_and(|e| e.success());
    out.push(Clause {
        name: "SIGTERM",
        pass: final_state.is_some() && final_status && clean,
        seen: format!(
            "final state (FINAL): {}, final status (finalized): {}, exit: {}",
            if final_state.is_some() { "yes" } else { "no" },
            if final_status { "yes" } else { "no" },
            match exit {
                Some(e) => describe(e),
                None => format!("still running after {:.1} s", stop_timeout.as_secs_f64()),
            }
        ),
    });
    driver.kill_and_reap();

    // 8. kill -9 and restart (free-running: the supervisor's restart path): the new
    // driver starts where the killed one stopped.
    if !rig.lockstep {
        out.push(restart_clause(rig, args, cfg, resolved, run_dir)?);
    }
    Ok(out)
}

/// Clauses of the torque phase: one state per torque or per period, header
/// bookkeeping, torques applied, lifecycle active, the arm held.
fn check_torque_phase(rig: &Rig, from: usize, t0: u64, t1: u64, unanswered: u32) -> Vec<Clause> {
    let states = &rig.states[from..];
    let mut out = Vec::new();
    let n = states.len();
    let secs = (t1 - t0) as f64 * 1e-9;
    let rate = n as f64 / secs;
    let want = 1e9 / rig.period.as_nanos() as f64;
    if rig.lockstep {
        let torques = rig.sent.len();
        out.push(Clause {
            name: "one state per torque",
            pass: unanswered == 0 && n == torques,
            seen: format!(
                "{torques} torques, {n} states, {unanswered} torques unanswered within 1 s"
            ),
        });
    } else {
        out.push(Clause {
            name: "state rate",
            pass: (rate - want).abs() <= 0.1 * want,
            seen: format!("{rate:.0} states/s (rate_hz {want:.0}, ±10 %)"),
        });
    }
    // Header bookkeeping: seq +1, torque_seq a torque sent, tick and source stamp of it.
    let mut seq_bad = 0;
    let mut copy_bad = Vec::new();
    let mut prev_seq = rig.states[..from].last().map(|s| s.state.header.seq);
    for s in states {
        let h = s.state.header;
        if prev_seq.is_some_and(|p| h.seq != p + 1) {
            seq_bad += 1;
        }
        prev_seq = Some(h.seq);
        let ts = s.state.torque_seq;
        if ts == u64::MAX {
            continue;
        }
        match ts.checked_sub(1).and_then(|i| rig.sent.get(i as usize)) {
            None => copy_bad.push(format!("torque_seq {ts} was never sent")),
            Some(t) => {
                let tick_ok = if rig.lockstep {
                    h.tick == t.tick
                } else {
                    h.tick >= t.tick
                };
                if !tick_ok || h.source_stamp_ns != t.source_stamp_ns {
                    copy_bad.push(format!(
                        "state {} for torque {ts}: tick {} (torque's {}), source_stamp_ns {} (torque's {})",
                        h.seq, h.tick, t.tick, h.source_stamp_ns, t.source_stamp_ns
                    ));
                }
            }
        }
    }
    out.push(Clause {
        name: "state sequence",
        pass: seq_bad == 0 && n > 0,
        seen: format!("{n} states, {seq_bad} where header.seq was not the previous + 1"),
    });
    out.push(Clause {
        name: "tick and stamp copied",
        pass: copy_bad.is_empty() && n > 0,
        seen: copy_bad.first().cloned().map_or_else(
            || {
                "every state carries the tick and source_stamp_ns of the torque it applied"
                    .to_string()
            },
            |first| format!("{} states wrong, first: {first}", copy_bad.len()),
        ),
    });
    // Torques applied and lifecycle active once the first torque arrived.
    let dof = rig.dof;
    let mut applied_bad = 0;
    let mut inactive = 0;
    let mut worst_q: f64 = 0.0;
    // Equal to 1e-6, or within half a step of a drive that quantises torque (and the
    // rounding error of the scaling factors).
    let tolerance = |i: usize, tau: f64| match &rig.torque_resolution {
        Some(r) => 0.5 * r[i] * (1.0 + 1e-9) + 1e-12,
        None => 1e-6 * (1.0 + tau.abs()),
    };
    for s in states {
        let st = &s.state;
        if st.torque_seq == u64::MAX {
            continue;
        }
        if st.lifecycle != LifecycleState::Active as u32 {
            inactive += 1;
        }
        if let Some(t) = st
            .torque_seq
            .checked_sub(1)
            .and_then(|i| rig.sent.get(i as usize))
            && st.flags
                & (state_flags::SATURATED
                    | state_flags::SLOPE_LIMITED
                    | state_flags::COMMAND_STALE
                    | state_flags::SAFE_STATE)
                == 0
            && (0..dof).any(|i| (st.tau_applied[i] - t.tau[i]).abs() > tolerance(i, t.tau[i]))
        {
            applied_bad += 1;
        }
        for i in 0..dof {
            worst_q = worst_q.max((st.q[i] - rig.hold_q[i]).abs());
        }
    }
    out.push(Clause {
        name: "lifecycle active",
        pass: inactive == 0 && n > 0,
        seen: format!("{inactive} states after the first torque not active"),
    });
    let within = match &rig.torque_resolution {
        Some(r) => format!(
            "by more than half the torque resolution ({:.4?} N·m / 2)",
            &r.as_slice()[..dof]
        ),
        None => "by more than 1e-6".to_string(),
    };
    out.push(Clause {
        name: "torque applied",
        pass: applied_bad == 0 && n > 0,
        seen: format!(
            "{applied_bad} states whose tau_applied differs from the torque they name {within} (neither saturated nor slope-limited); the hold law kept q within {worst_q:.2e} of its start"
        ),
    });
    out
}

/// The status clause: rate, identity, counters the run's summary reads.
fn check_status(rig: &Rig, from: usize, cfg: &PipelineConfig) -> Clause {
    let sts = &rig.statuses[from..];
    let want_hz = 1000.0 / cfg.status_period_ms;
    let mut bad = Vec::new();
    let span = match (sts.first(), sts.last()) {
        (Some(a), Some(b)) if sts.len() >= 2 => (b.stamp_ns - a.stamp_ns) as f64 * 1e-9,
        _ => 0.0,
    };
    let hz = if span > 0.0 {
        (sts.len() - 1) as f64 / span
    } else {
        0.0
    };
    if !(0.5 * want_hz..=2.0 * want_hz).contains(&hz) {
        bad.push(format!("{hz:.1} statuses/s (want ~{want_hz:.0})"));
    }
    if let Some(last) = sts.last() {
        if last.ready != 1 {
            bad.push("ready 0".to_string());
        }
        if last.lifecycle != LifecycleState::Active as u32 {
            bad.push(format!("lifecycle {}", lifecycle_name(last.lifecycle)));
        }
        if last.cycles == 0 {
            bad.push("cycles 0".to_string());
        }
        if last.latency.count == 0 || last.latency.p50_ns == 0 {
            bad.push(
                "latency left at zero (the run's end-to-end latency would read 0)".to_string(),
            );
        }
        if last.peak_torque[..rig.dof].iter().all(|t| *t == 0.0) {
            bad.push("peak_torque left at zero".to_string());
        }
    } else {
        bad.push("no status during the torques".to_string());
    }
    Clause {
        name: "status",
        pass: bad.is_empty(),
        seen: if bad.is_empty() {
            format!(
                "{hz:.1}/s, ready, active, cycles {}, latency p50 {:.1} µs",
                sts.last().map_or(0, |s| s.cycles),
                sts.last().map_or(0.0, |s| s.latency.p50_ns as f64 / 1000.0)
            )
        } else {
            bad.join("; ")
        },
    }
}

/// Every state and status is followed by a `notify()` on its event service: the planner
/// and dynamics sleep on the state event, the supervisor and monitors on the status one.
fn check_notify(n: &Notified) -> Clause {
    let mut bad = Vec::new();
    for (what, polls, events) in [
        ("state", n.state_polls, n.state_events),
        ("status", n.status_polls, n.status_events),
    ] {
        if polls == 0 || 2 * events < polls {
            bad.push(format!(
                "{what}: {events} wake-ups for {polls} polls that found new {what}s"
            ));
        }
    }
    Clause {
        name: "notify",
        pass: bad.is_empty(),
        seen: if bad.is_empty() {
            format!(
                "state events on {} of {} polls with new states, status events on {} of {}",
                n.state_events, n.state_polls, n.status_events, n.status_polls
            )
        } else {
            format!("{} (each must be followed by notify())", bad.join("; "))
        },
    }
}

/// kill -9 mid-motion, restart with the last state in `MICROROBOT_RESUME_STATE`: the
/// restarted driver's first state is where the killed one stopped.
fn restart_clause(
    rig: &mut Rig,
    args: &DriverCheckArgs,
    cfg: &PipelineConfig,
    resolved: &Path,
    run_dir: &Path,
) -> anyhow::Result<Clause> {
    // A fresh driver, driven, then killed.
    let mut first = Service::spawn(launch(args, cfg, resolved, run_dir, None))?;
    let ready_timeout = Duration::from_secs_f64(cfg.supervisor.ready_timeout_ms / 1000.0);
    let pid = first.pid();
    let n0 = rig.states.len();
    let ok = rig.wait(ready_timeout, |r| {
        r.states.len() > n0
            && r.statuses
                .last()
                .is_some_and(|s| s.pid == pid && s.ready == 1)
    })?;
    if !ok {
        first.kill_and_reap();
        return Ok(Clause {
            name: "kill -9 and restart",
            pass: false,
            seen: "the driver did not start again after SIGTERM (no ready status or state)".into(),
        });
    }
    rig.hold_q = vec8(&rig.states[rig.states.len() - 1].state.q);
    rig.drive(Duration::from_millis(500), true)?;
    first.signal(libc::SIGKILL);
    first.kill_and_reap();
    rig.pump()?;
    let Some(last) = rig.last_state().copied() else {
        anyhow::bail!("no state before the kill");
    };
    let resume = microrobot_actuator::resume::encode(&last);
    let mut second = Service::spawn(launch(args, cfg, resolved, run_dir, Some(resume)))?;
    let pid2 = second.pid();
    let n1 = rig.states.len();
    let ok = rig.wait(ready_timeout, |r| {
        r.states.len() > n1
            && r.statuses
                .last()
                .is_some_and(|s| s.pid == pid2 && s.ready == 1)
    })?;
    let first_after = rig.states.get(n1).map(|s| s.state);
    second.signal(libc::SIGTERM);
    let end = Instant::now() + Duration::from_secs_f64(cfg.supervisor.stop_timeout_ms / 1000.0);
    while second.poll_exit().is_none() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(5));
    }
    second.kill_and_reap();
    let Some(after) = first_after.filter(|_| ok) else {
        return Ok(Clause {
            name: "kill -9 and restart",
            pass: false,
            seen: "the restarted driver published no state".into(),
        });
    };
    let jump = (0..rig.dof)
        .map(|i| (after.q[i] - last.q[i]).abs())
        .fold(0.0, f64::max);
    // Encoder resolution: a simulated plant resumes exactly, a drive within its counts.
    const RESOLUTION: f64 = 1e-4;
    Ok(Clause {
        name: "kill -9 and restart",
        pass: jump <= RESOLUTION,
        seen: format!(
            "first state after the restart {jump:.2e} from the last before the kill (≤ {RESOLUTION:e}: encoder resolution)"
        ),
    })
}
