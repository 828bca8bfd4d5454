//! `microrobot-example-driver`: an actuator driver written against the bus contract
//! (`microrobot-messages`) alone, to prove that the contract is enough to take the
//! actuator's place.
//!
//! It is a *loopback* drive: it applies each torque command's `q_desired` as the measured
//! position (a perfectly stiff position-controlled joint), differentiates it for the
//! velocity, and publishes one `JointState` per torque command — the same shape a real
//! drive in cyclic-synchronous mode would have, with its own position loop inside.
//! It publishes `ServiceStatus` (role actuator) at ~10 Hz and a final one
//! (lifecycle `Finalized`) on SIGINT/SIGTERM, then exits 0.
//!
//! ```text
//! microrobot-example-driver [--instance NAME] [--rate-hz HZ] [--dof N] [--q0-deg a,b,..]
//! ```
//! Defaults come from the environment the supervisor sets: `MICROROBOT_INSTANCE`,
//! `MICROROBOT_RATE_HZ`.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use iceoryx2::prelude::*;
use microrobot_messages::{
    Header, JointState, LatencySummary, LifecycleState, MAX_JOINTS, ServiceKind, ServiceRole,
    ServiceStatus, TorqueCommand, all_finite, monotonic_ns, open_event, open_publish_subscribe,
};

/// Status period (the contract asks for ~10 Hz).
const STATUS_PERIOD_NS: u64 = 100_000_000;
/// Period of the measured state before the first torque command (and of the wait loop).
const IDLE_STATE_PERIOD_MS: u64 = 5;

/// Command-line options.
#[derive(Debug, Clone)]
struct Options {
    instance: String,
    rate_hz: f64,
    dof: u32,
    q0: [f64; MAX_JOINTS],
}

fn parse_options() -> Result<Options, String> {
    let mut opts = Options {
        instance: std::env::var("MICROROBOT_INSTANCE").unwrap_or_else(|_| "default".into()),
        rate_hz: 1000.0,
        dof: 6,
        q0: [0.0; MAX_JOINTS],
    };
    if let Ok(v) = std::env::var("MICROROBOT_RATE_HZ") {
        opts.rate_hz = parse_rate(&v)?;
    }
    let mut q0_given: Option<Vec<f64>> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--instance" => opts.instance = value("--instance")?,
            "--rate-hz" => opts.rate_hz = parse_rate(&value("--rate-hz")?)?,
            "--dof" => {
                let v = value("--dof")?;
                opts.dof = v
                    .parse()
                    .ok()
                    .filter(|d| (1..=MAX_JOINTS as u32).contains(d))
                    .ok_or(format!("--dof must be 1..={MAX_JOINTS}, got `{v}`"))?;
            }
            "--q0-deg" => {
                let v = value("--q0-deg")?;
                let parsed: Result<Vec<f64>, _> =
                    v.split(',').map(|s| s.trim().parse::<f64>()).collect();
                let parsed = parsed.map_err(|e| format!("--q0-deg `{v}`: {e}"))?;
                if parsed.iter().any(|x| !x.is_finite()) {
                    return Err(format!("--q0-deg `{v}`: values must be finite"));
                }
                q0_given = Some(parsed);
            }
            "-h" | "--help" => {
                return Err(
                    "usage: microrobot-example-driver [--instance NAME] [--rate-hz HZ] [--dof N] [--q0-deg a,b,..]"
                        .into(),
                );
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    if let Some(q0) = q0_given {
        if q0.len() != opts.dof as usize {
            return Err(format!(
                "--q0-deg has {} values but --dof is {}",
                q0.len(),
                opts.dof
            ));
        }
        for (slot, deg) in opts.q0.iter_mut().zip(q0) {
            *slot = deg.to_radians();
        }
    }
    Ok(opts)
}

fn parse_rate(v: &str) -> Result<f64, String> {
    v.parse::<f64>()
        .ok()
        .filter(|r| r.is_finite() && *r > 0.0)
        .ok_or(format!("rate must be a positive number of Hz, got `{v}`"))
}

/// Latencies of the last cycles, for the status percentiles (allocated once).
struct LatencyWindow {
    samples: Vec<u64>,
    next: usize,
    count: u64,
    max: u64,
    scratch: Vec<u64>,
}

impl LatencyWindow {
    fn new(capacity: usize) -> Self {
        Self {
            samples: Vec::with_capacity(capacity),
            next: 0,
            count: 0,
            max: 0,
            scratch: Vec::with_capacity(capacity),
        }
    }

    fn record(&mut self, ns: u64) {
        if self.samples.len() < self.samples.capacity() {
            self.samples.push(ns);
        } else {
            self.samples[self.next] = ns;
            self.next = (self.next + 1) % self.samples.len();
        }
        self.count += 1;
        self.max = self.max.max(ns);
    }

    /// Percentiles over the window; `max` over the whole run.
    fn summary(&mut self) -> LatencySummary {
        if self.samples.is_empty() {
            return LatencySummary::default();
        }
        self.scratch.clear();
        self.scratch.extend_from_slice(&self.samples);
        self.scratch.sort_unstable();
        let at = |q: f64| {
            let i = ((self.scratch.len() as f64 - 1.0) * q).round() as usize;
            self.scratch[i.min(self.scratch.len() - 1)]
        };
        LatencySummary {
            count: self.count,
            p50_ns: at(0.50),
            p99_ns: at(0.99),
            p999_ns: at(0.999),
            p9999_ns: at(0.9999),
            max_ns: self.max,
        }
    }
}

/// The loopback plant and its counters.
struct Driver {
    opts: Options,
    state_seq: u64,
    q: [f64; MAX_JOINTS],
    qd: [f64; MAX_JOINTS],
    last_tick: Option<u64>,
    last_torque_seq: Option<u64>,
    cycles: u64,
    lost: u64,
    refused: u64,
    peak_torque: [f64; MAX_JOINTS],
    motion_time_s: f64,
    latency: LatencyWindow,
    status_seq: u64,
}

impl Driver {
    fn new(opts: Options) -> Self {
        Self {
            q: opts.q0,
            opts,
            state_seq: 0,
            qd: [0.0; MAX_JOINTS],
            last_tick: None,
            last_torque_seq: None,
            cycles: 0,
            lost: 0,
            refused: 0,
            peak_torque: [0.0; MAX_JOINTS],
            motion_time_s: 0.0,
            latency: LatencyWindow::new(8192),
            status_seq: 0,
        }
    }

    /// Applies one torque command; returns the state to publish, or `None` if refused.
    fn apply(&mut self, cmd: &TorqueCommand, received_ns: u64) -> Option<JointState> {
        if let Some(prev) = self.last_torque_seq {
            if cmd.header.seq <= prev {
                self.refused += 1;
                return None;
            }
            self.lost += cmd.header.seq - prev - 1;
        }
        self.last_torque_seq = Some(cmd.header.seq);
        if cmd.dof != self.opts.dof || !all_finite(&cmd.q_desired, cmd.dof) {
            self.refused += 1;
            return None;
        }
        self.latency
            .record(received_ns.saturating_sub(cmd.header.source_stamp_ns));
        let dof = self.opts.dof as usize;
        let dt = match self.last_tick {
            Some(t) if cmd.header.tick > t => (cmd.header.tick - t) as f64 / self.opts.rate_hz,
            _ => 0.0,
        };
        for j in 0..dof {
            let q_new = cmd.q_desired[j];
            self.qd[j] = if dt > 0.0 {
                (q_new - self.q[j]) / dt
            } else {
                0.0
            };
            self.q[j] = q_new;
            if cmd.tau[j].is_finite() {
                self.peak_torque[j] = self.peak_torque[j].max(cmd.tau[j].abs());
            }
        }
        self.last_tick = Some(cmd.header.tick);
        self.motion_time_s = cmd.header.tick as f64 / self.opts.rate_hz;
        self.cycles += 1;
        Some(self.state(
            cmd.header.tick,
            cmd.header.source_stamp_ns,
            cmd.header.seq,
            cmd.tau,
        ))
    }

    fn state(
        &mut self,
        tick: u64,
        source_stamp_ns: u64,
        torque_seq: u64,
        tau: [f64; MAX_JOINTS],
    ) -> JointState {
        self.state_seq += 1;
        let now = monotonic_ns();
        JointState {
            header: Header {
                seq: self.state_seq,
                tick,
                stamp_ns: now,
                source_stamp_ns: if source_stamp_ns == 0 {
                    now
                } else {
                    source_stamp_ns
                },
            },
            q: self.q,
            qd: self.qd,
            tau_applied: tau,
            torque_seq,
            dof: self.opts.dof,
            lifecycle: LifecycleState::Active as u32,
            flags: 0,
            reserved: 0,
        }
    }

    fn status(&mut self, lifecycle: LifecycleState) -> ServiceStatus {
        self.status_seq += 1;
        ServiceStatus {
            seq: self.status_seq,
            stamp_ns: monotonic_ns(),
            role: ServiceRole::Actuator as u32,
            lifecycle: lifecycle as u32,
            pid: std::process::id(),
            ready: 1,
            cycles: self.cycles,
            lost_messages: self.lost,
            refused_messages: self.refused,
            motion_time_s: self.motion_time_s,
            latency: self.latency.summary(),
            // A loopback drive reaches its commanded position exactly.
            tracking_error_max: [0.0; MAX_JOINTS],
            peak_torque: self.peak_torque,
            ..ServiceStatus::default()
        }
    }
}

fn run(opts: Options) -> Result<(), String> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| format!("cannot install the SIGINT/SIGTERM handler: {e}"))?;

    let node_name: NodeName = "example-driver"
        .try_into()
        .map_err(|e| format!("node name: {e:?}"))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| format!("cannot create the iceoryx2 node: {e:?}"))?;
    let instance = opts.instance.as_str();
    let bus = |e: microrobot_messages::BusError| e.to_string();

    let torque_sub = open_publish_subscribe::<TorqueCommand>(&node, instance, ServiceKind::Torque)
        .map_err(bus)?
        .subscriber_builder()
        .create()
        .map_err(|e| format!("torque subscriber: {e:?}"))?;
    let torque_listener = open_event(&node, instance, ServiceKind::Torque)
        .map_err(bus)?
        .listener_builder()
        .create()
        .map_err(|e| format!("torque listener: {e:?}"))?;
    let state_pub = open_publish_subscribe::<JointState>(&node, instance, ServiceKind::State)
        .map_err(bus)?
        .publisher_builder()
        .create()
        .map_err(|e| format!("state publisher: {e:?}"))?;
    let state_notifier = open_event(&node, instance, ServiceKind::State)
        .map_err(bus)?
        .notifier_builder()
        .create()
        .map_err(|e| format!("state notifier: {e:?}"))?;
    let status_pub = open_publish_subscribe::<ServiceStatus>(&node, instance, ServiceKind::Status)
        .map_err(bus)?
        .publisher_builder()
        .create()
        .map_err(|e| format!("status publisher: {e:?}"))?;

    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| format!("waitset: {e:?}"))?;
    let on_torque = waitset
        .attach_notification(&torque_listener)
        .map_err(|e| format!("waitset attach: {e:?}"))?;

    let mut driver = Driver::new(opts);
    // Until the first torque command arrives, report the measured state every few ms
    // like a real drive does: the planner starts its motion from a fresh one.
    let mut next_idle_state_ns = 0;
    let mut next_status_ns = 0;
    let mut error: Option<String> = None;

    while !stop.load(Ordering::SeqCst) {
        let result = waitset.wait_and_process_once_with_timeout(
            |id| {
                if id.has_event_from(&on_torque) {
                    // Always drain the listener, or the level-triggered fd spins.
                    let _ = torque_listener.try_wait(|_| {});
                    loop {
                        let cmd = match torque_sub.receive() {
                            Ok(Some(sample)) => *sample,
                            Ok(None) => break,
                            Err(e) => {
                                error = Some(format!("torque receive: {e:?}"));
                                return CallbackProgression::Stop;
                            }
                        };
                        if let Some(state) = driver.apply(&cmd, monotonic_ns()) {
                            if let Err(e) = state_pub.send_copy(state) {
                                error = Some(format!("state publish: {e:?}"));
                                return CallbackProgression::Stop;
                            }
                            let _ = state_notifier.notify();
                        }
                    }
                }
                CallbackProgression::Continue
            },
            Duration::from_millis(IDLE_STATE_PERIOD_MS),
        );
        if let Err(e) = result {
            return Err(format!("waitset: {e:?}"));
        }
        if let Some(e) = error.take() {
            return Err(e);
        }
        let now = monotonic_ns();
        if driver.cycles == 0 && now >= next_idle_state_ns {
            next_idle_state_ns = now + IDLE_STATE_PERIOD_MS * 1_000_000;
            let idle = driver.state(0, 0, u64::MAX, [0.0; MAX_JOINTS]);
            state_pub
                .send_copy(idle)
                .map_err(|e| format!("publish initial state: {e:?}"))?;
            let _ = state_notifier.notify();
        }
        if now >= next_status_ns {
            next_status_ns = now + STATUS_PERIOD_NS;
            status_pub
                .send_copy(driver.status(LifecycleState::Active))
                .map_err(|e| format!("status publish: {e:?}"))?;
        }
    }
    status_pub
        .send_copy(driver.status(LifecycleState::Finalized))
        .map_err(|e| format!("final status publish: {e:?}"))?;
    Ok(())
}

fn main() -> ExitCode {
    let opts = match parse_options() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("microrobot-example-driver: {e}");
            return ExitCode::from(2);
        }
    };
    match run(opts) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("microrobot-example-driver: {e}");
            ExitCode::FAILURE
        }
    }
}
