//! Helpers of the system tests: start the real `microrobot` binary with a config of the
//! test's own (unique instance name), wait with generous guards, record the bus streams
//! from the test process, read the summary.
#![allow(dead_code)]

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use microrobot_messages::{
    CommandKind, JointSetpoint, JointState, MotionCommand, ProfileKind, ServiceKind, ServiceRole,
    ServiceStatus, TargetSpace, TorqueCommand, monotonic_ns, open_event, open_publish_subscribe,
    service_name,
};

/// The `microrobot` binary under test.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_microrobot")
}

/// The binary `name` of another workspace package (`package`), of this build.
/// `cargo test --workspace` builds it with everything else; when it is older than any
/// source it is built from (`Cargo.lock`, the manifests, `messages/`, `services/` and
/// the package's own folders `dirs`: after an edit and a narrower `cargo test`), it is
/// built here first, since a stale binary from before a contract change would fail to
/// open the bus. (Building it unconditionally costs a second dependency tree: `cargo
/// build -p` resolves other features than the workspace's tests.)
pub fn workspace_binary(name: &str, package: &str, dirs: &[&str]) -> PathBuf {
    let exe = Path::new(bin()).parent().expect("binary dir").join(name);
    let built = std::fs::metadata(&exe).and_then(|m| m.modified()).ok();
    let newest = ["Cargo.lock", "Cargo.toml", "messages", "services"]
        .iter()
        .chain(dirs)
        .filter_map(|s| newest_mtime(&repo().join(s)))
        .max();
    if built.is_none() || newest > built {
        // The profile of the `microrobot` under test (`target/debug` is `dev`), so that a
        // `cargo test --release` rebuilds the binary it runs, not a debug one beside it.
        let dir = exe.parent().and_then(Path::file_name);
        let profile = match dir.and_then(|d| d.to_str()) {
            Some("debug") | None => "dev",
            Some(p) => p,
        };
        let status = Command::new(env!("CARGO"))
            .args(["build", "--profile", profile, "-p", package, "--bin", name])
            .current_dir(repo())
            .status()
            .unwrap_or_else(|e| panic!("cargo build -p {package}: {e}"));
        assert!(status.success(), "building {name} failed");
    }
    assert!(exe.exists(), "{} missing", exe.display());
    exe
}

/// The newest modification time of a file or of any file below a folder.
fn newest_mtime(path: &Path) -> Option<std::time::SystemTime> {
    let meta = std::fs::metadata(path).ok()?;
    if !meta.is_dir() {
        return meta.modified().ok();
    }
    std::fs::read_dir(path)
        .ok()?
        .flatten()
        .filter_map(|e| newest_mtime(&e.path()))
        .max()
}

/// The simulated arm's service binary (`microrobot-actuator`) of the same build.
pub fn actuator_bin() -> &'static str {
    env!("CARGO_BIN_EXE_microrobot-actuator")
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A unique instance name for one test (test name + pid).
pub fn instance(test: &str) -> String {
    format!("t-{test}-{}", std::process::id())
}

/// The seed's Table 4 program.
pub fn table4_program() -> PathBuf {
    repo().join("config/programs/seed-table4.toml")
}

/// The seed arm.
pub fn seed_arm() -> PathBuf {
    repo().join("config/robots/seed-arm.toml")
}

/// The limits of the seed arm, for the stream invariants.
pub fn seed_arm_limits() -> microrobot_bus_tools::invariants::Limits {
    let robot = microrobot_model::Robot::from_file(&seed_arm()).expect("seed arm");
    microrobot_bus_tools::invariants::Limits::of(&robot)
}

/// Top-level config lines that run the seed's Table 4 program in lockstep.
pub fn table4_lockstep_lines() -> String {
    format!(
        "program = \"{}\"\nlockstep = true",
        table4_program().display()
    )
}

/// Writes a pipeline config for `instance` into `dir`: the seed arm, real time settings
/// that need no privileges, and `extra` TOML appended (top-level keys first, then tables).
pub fn write_config(dir: &Path, instance: &str, top_level: &str, tables: &str) -> PathBuf {
    let text = format!(
        "instance = \"{instance}\"\nrobot = \"{}\"\n{top_level}\n\n[realtime]\ncpu_affinity = []\npm_qos = false\nmlockall = false\n\n{tables}\n",
        seed_arm().display()
    );
    let path = dir.join(format!("{instance}.toml"));
    std::fs::write(&path, text).expect("write test config");
    path
}

/// A started process whose output is collected.
pub struct Proc {
    pub child: Child,
    started: Instant,
}

/// Output of a finished process.
#[derive(Debug)]
pub struct Finished {
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

impl Finished {
    pub fn code(&self) -> Option<i32> {
        self.status.code()
    }
}

/// Starts `microrobot <args>`.
pub fn start(args: &[&str]) -> Proc {
    let child = Command::new(bin())
        .args(args)
        .current_dir(repo())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start microrobot");
    Proc {
        child,
        started: Instant::now(),
    }
}

impl Proc {
    /// Wraps a child started by the test itself (stdout and stderr piped).
    pub fn from_child(child: Child) -> Self {
        Self {
            child,
            started: Instant::now(),
        }
    }

    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    pub fn signal(&self, sig: i32) {
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(self.pid(), sig) };
    }

    /// Waits (guard: `guard_s` seconds, then SIGKILL and panic) and collects output.
    pub fn finish(mut self, guard_s: f64) -> Finished {
        let mut out = self.child.stdout.take().expect("stdout");
        let mut err = self.child.stderr.take().expect("stderr");
        let t_out = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        let t_err = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = err.read_to_string(&mut s);
            s
        });
        let deadline = self.started + Duration::from_secs_f64(guard_s);
        let status = loop {
            if let Some(st) = self.child.try_wait().expect("try_wait") {
                break st;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                let stderr = t_err.join().unwrap_or_default();
                panic!("microrobot did not finish within the {guard_s} s guard; stderr:\n{stderr}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        Finished {
            status,
            stdout: t_out.join().unwrap_or_default(),
            stderr: t_err.join().unwrap_or_default(),
        }
    }
}

/// Runs `microrobot <args>` to the end (guard `guard_s`).
pub fn run(args: &[&str], guard_s: f64) -> Finished {
    start(args).finish(guard_s)
}

/// Reads a `--summary-json` file.
pub fn summary(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("summary {} missing: {e}", path.display()));
    serde_json::from_str(&text).expect("summary is JSON")
}

/// The per-joint array `key` of a summary.
pub fn joints(summary: &serde_json::Value, key: &str) -> Vec<f64> {
    summary[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key} missing in {summary}"))
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect()
}

pub fn max_of(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

fn node(name: &str) -> Node<ipc::Service> {
    NodeBuilder::new()
        .name(&NodeName::new(name).expect("node name"))
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .expect("iceoryx2 node")
}

/// Everything a [`Recorder`] saw.
#[derive(Debug, Default, Clone)]
pub struct Streams {
    pub setpoints: Vec<JointSetpoint>,
    pub torques: Vec<TorqueCommand>,
    pub states: Vec<JointState>,
    pub statuses: Vec<ServiceStatus>,
}

/// Records the setpoint, torque, state and status streams of an instance from a thread
/// of the test process (an independent subscriber, as a monitor would be).
pub struct Recorder {
    stop: Arc<AtomicBool>,
    ready: Arc<AtomicBool>,
    handle: Option<JoinHandle<Streams>>,
}

impl Recorder {
    /// Subscribes before the pipeline starts (the services are created here if needed,
    /// with the contract's QoS), so nothing is missed.
    pub fn start(instance: &str) -> Self {
        Self::spawn(instance, true, false)
    }

    /// Like [`Recorder::start`], but polls without sleeping (lockstep runs outpace a
    /// sleeping poller's queue of `SUBSCRIBER_BUFFER`).
    pub fn start_spinning(instance: &str) -> Self {
        Self::spawn(instance, true, true)
    }

    /// Records only the status stream.
    pub fn start_statuses(instance: &str) -> Self {
        Self::spawn(instance, false, false)
    }

    fn spawn(instance: &str, data: bool, spin: bool) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let ready = Arc::new(AtomicBool::new(false));
        let (s, r) = (stop.clone(), ready.clone());
        let instance = instance.to_string();
        let handle = std::thread::spawn(move || {
            let node = node(&format!("microrobot-test-recorder-{}", std::process::id()));
            let sp = data.then(|| {
                open_publish_subscribe::<JointSetpoint>(&node, &instance, ServiceKind::Setpoint)
                    .expect("setpoint service")
                    .subscriber_builder()
                    .create()
                    .expect("setpoint subscriber")
            });
            let tq = data.then(|| {
                open_publish_subscribe::<TorqueCommand>(&node, &instance, ServiceKind::Torque)
                    .expect("torque service")
                    .subscriber_builder()
                    .create()
                    .expect("torque subscriber")
            });
            let st = data.then(|| {
                open_publish_subscribe::<JointState>(&node, &instance, ServiceKind::State)
                    .expect("state service")
                    .subscriber_builder()
                    .create()
                    .expect("state subscriber")
            });
            let stat =
                open_publish_subscribe::<ServiceStatus>(&node, &instance, ServiceKind::Status)
                    .expect("status service")
                    .subscriber_builder()
                    .create()
                    .expect("status subscriber");
            r.store(true, Ordering::SeqCst);
            let mut out = Streams::default();
            loop {
                let stopping = s.load(Ordering::SeqCst);
                let mut n = 0;
                while let Some(Ok(Some(x))) = sp.as_ref().map(|p| p.receive()) {
                    out.setpoints.push(*x);
                    n += 1;
                }
                while let Some(Ok(Some(x))) = tq.as_ref().map(|p| p.receive()) {
                    out.torques.push(*x);
                    n += 1;
                }
                while let Some(Ok(Some(x))) = st.as_ref().map(|p| p.receive()) {
                    out.states.push(*x);
                    n += 1;
                }
                while let Ok(Some(x)) = stat.receive() {
                    out.statuses.push(*x);
                    n += 1;
                }
                if stopping {
                    break;
                }
                if n == 0 {
                    if spin {
                        std::thread::yield_now();
                    } else {
                        std::thread::sleep(Duration::from_micros(200));
                    }
                }
            }
            out
        });
        let rec = Self {
            stop,
            ready,
            handle: Some(handle),
        };
        let t0 = Instant::now();
        while !rec.ready.load(Ordering::SeqCst) {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "recorder did not start"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        rec
    }

    /// Stops recording and returns the streams.
    pub fn finish(mut self) -> Streams {
        self.stop.store(true, Ordering::SeqCst);
        self.handle
            .take()
            .expect("recorder running")
            .join()
            .expect("recorder thread")
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Asserts that `seqs` has no gaps (the recorder lost nothing).
pub fn assert_no_gaps(what: &str, seqs: impl Iterator<Item = u64>) {
    let mut prev: Option<u64> = None;
    for s in seqs {
        if let Some(p) = prev {
            assert_eq!(
                s,
                p + 1,
                "{what}: sequence gap {p} -> {s} (the recorder lost samples)"
            );
        }
        prev = Some(s);
    }
}

/// Waits until every service of `instance` reported ready (guard `guard_s`).
pub fn wait_ready(instance: &str, guard_s: f64) {
    let node = node(&format!("microrobot-test-waiter-{}", std::process::id()));
    let sub = open_publish_subscribe::<ServiceStatus>(&node, instance, ServiceKind::Status)
        .expect("status service")
        .subscriber_builder()
        .create()
        .expect("status subscriber");
    let mut ready = [false; 3];
    let t0 = Instant::now();
    while !ready.iter().all(|r| *r) {
        while let Ok(Some(s)) = sub.receive() {
            if s.ready == 1 {
                match ServiceRole::from_wire(s.role) {
                    Some(ServiceRole::Planner) => ready[0] = true,
                    Some(ServiceRole::Dynamics) => ready[1] = true,
                    Some(ServiceRole::Actuator) => ready[2] = true,
                    None => {}
                }
            }
        }
        assert!(
            t0.elapsed().as_secs_f64() < guard_s,
            "pipeline `{instance}` not ready within {guard_s} s (ready: {ready:?})"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Services of `instance` that still exist in iceoryx2.
pub fn remaining_services(instance: &str) -> Vec<String> {
    let prefix = service_name(instance, ServiceKind::Status);
    let prefix = prefix.trim_end_matches("status").to_string();
    let mut found = Vec::new();
    let _ = <ipc::Service as iceoryx2::service::Service>::list(Config::global_config(), |d| {
        let name = d.static_details.name().as_str().to_string();
        if name.starts_with(&prefix) {
            found.push(name);
        }
        CallbackProgression::Continue
    });
    found
}

/// Live or dead iceoryx2 nodes of `instance`'s processes.
pub fn remaining_nodes(instance: &str) -> Vec<String> {
    let prefix = format!("microrobot.{instance}.");
    let mut found = Vec::new();
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        use iceoryx2::node::NodeView;
        let details = match &state {
            NodeState::Alive(v) => v.details().clone(),
            NodeState::Dead(v) => v.details().clone(),
            _ => None,
        };
        if let Some(d) = details
            && d.name().as_str().starts_with(&prefix)
        {
            found.push(d.name().as_str().to_string());
        }
        CallbackProgression::Continue
    });
    found
}

/// Whether process `pid` still exists.
pub fn alive(pid: i32) -> bool {
    // SAFETY: signal 0 only checks existence.
    unsafe { libc::kill(pid, 0) == 0 }
}

/// The pid of the ready `role` service of `instance`, from a short look at the status
/// stream (statuses come at ~10 Hz); `None` if none reported.
pub fn pid_of(instance: &str, role: ServiceRole) -> Option<i32> {
    let rec = Recorder::start_statuses(instance);
    std::thread::sleep(Duration::from_millis(300));
    rec.finish()
        .statuses
        .iter()
        .rev()
        .find(|s| s.role == role as u32 && s.ready == 1)
        .map(|s| s.pid as i32)
}

/// Waits until a `role` service other than `old_pid` reports ready (a restart), guard
/// `guard_s`; returns its pid.
pub fn wait_restarted(instance: &str, role: ServiceRole, old_pid: i32, guard_s: f64) -> i32 {
    let t0 = Instant::now();
    loop {
        if let Some(p) = pid_of(instance, role)
            && p != old_pid
        {
            return p;
        }
        assert!(
            t0.elapsed().as_secs_f64() < guard_s,
            "{} of `{instance}` not restarted within {guard_s} s",
            role.name()
        );
    }
}

/// `microrobot send --instance <instance> --config <config> <args>` to the end.
pub fn send(instance: &str, config: &Path, args: &[&str]) -> Finished {
    let cfg = config.to_str().expect("utf-8 path");
    let mut all = vec!["send", "--instance", instance, "--config", cfg];
    all.extend_from_slice(args);
    run(&all, 60.0)
}

/// Starts `microrobot run --config CFG --no-program --duration S [--summary-json FILE]`
/// (a pipeline holding the arm, to be commanded by the test) and waits until every
/// service of `instance` is ready.
pub fn start_holding(instance: &str, cfg: &Path, duration_s: u32, summary: Option<&Path>) -> Proc {
    let cfg_s = cfg.to_str().expect("utf-8 config path").to_string();
    let dur = duration_s.to_string();
    let mut args = vec![
        "run",
        "--config",
        &cfg_s,
        "--no-program",
        "--duration",
        &dur,
    ];
    let sum_s = summary.map(|p| p.to_str().expect("utf-8 summary path").to_string());
    if let Some(s) = &sum_s {
        args.extend_from_slice(&["--summary-json", s]);
    }
    let proc = start(&args);
    wait_ready(instance, 60.0);
    proc
}

/// Publishes motion commands into an instance from the test process (any client may
/// command the planner), without the round trip of a `microrobot send` process, so
/// commands land at the moments the test chooses.
pub struct CommandSender {
    _node: Node<ipc::Service>,
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, MotionCommand, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    seq: u64,
}

impl CommandSender {
    /// Opens the command stream of `instance` (a running pipeline's planner subscribes
    /// to it before it reports ready).
    pub fn open(instance: &str) -> Self {
        let node = node(&format!("microrobot-test-commander-{}", std::process::id()));
        let publisher =
            open_publish_subscribe::<MotionCommand>(&node, instance, ServiceKind::Command)
                .expect("command service")
                .publisher_builder()
                .create()
                .expect("command publisher");
        let notifier = open_event(&node, instance, ServiceKind::Command)
            .expect("command event")
            .notifier_builder()
            .create()
            .expect("command notifier");
        Self {
            _node: node,
            publisher,
            notifier,
            seq: 0,
        }
    }

    /// Sends `c` (numbered and stamped now).
    pub fn send(&mut self, mut c: MotionCommand) {
        self.seq += 1;
        c.seq = self.seq;
        c.stamp_ns = monotonic_ns();
        self.publisher.send_copy(c).expect("send command");
        let _ = self.notifier.notify();
    }
}

/// A command of `kind` with no target.
pub fn command(kind: CommandKind) -> MotionCommand {
    MotionCommand {
        kind: kind as u32,
        limit_scale: 1.0,
        ..Default::default()
    }
}

/// A time-optimal joint move to `q` (rad or m).
pub fn joint_move(q: &[f64]) -> MotionCommand {
    let mut c = command(CommandKind::Move);
    c.profile = ProfileKind::Soft as u32;
    c.space = TargetSpace::Joint as u32;
    c.dof = q.len() as u32;
    c.target[..q.len()].copy_from_slice(q);
    c
}

/// Waits until a status of `role` satisfies `f` (guard `guard_s`); returns it.
pub fn wait_status(
    instance: &str,
    role: ServiceRole,
    what: &str,
    guard_s: f64,
    f: impl Fn(&ServiceStatus) -> bool,
) -> ServiceStatus {
    let node = node(&format!("microrobot-test-status-{}", std::process::id()));
    let sub = open_publish_subscribe::<ServiceStatus>(&node, instance, ServiceKind::Status)
        .expect("status service")
        .subscriber_builder()
        .create()
        .expect("status subscriber");
    let t0 = Instant::now();
    loop {
        while let Ok(Some(s)) = sub.receive() {
            if s.role == role as u32 && f(&s) {
                return *s;
            }
        }
        assert!(
            t0.elapsed().as_secs_f64() < guard_s,
            "{} of `{instance}`: {what} not seen within {guard_s} s",
            role.name()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}
