//! `microrobot top`: a live view of a running pipeline. The services from their status
//! stream: cycles/s, each one's own timing p50/p99 (planner: wake-up lateness; dynamics:
//! setpoint → torque; actuator: end-to-end latency), misses, lost, refused, stale, faults,
//! lifecycle, silence (a live process whose status stopped is shown as hung), a blocking
//! lifecycle hook the actuator announced with its budget, the planner's e-stop latency;
//! then what the arm does: the planner's activity (program, move, hold, e-stop, safe
//! state, teleop) and program state, each joint's measured position and commanded
//! torque, and the tool pose; then the latency budget by hop (as in the run's summary,
//! counted since each service started). It exits when the pipeline ends.

use std::io::IsTerminal as _;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::ensure;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use microrobot_messages::{
    Activity, JointState, LifecycleHook, MAX_JOINTS, ProgramState, ServiceKind, ServiceRole,
    ServiceStatus, TorqueCommand, open_publish_subscribe,
};
use microrobot_model::{JointKind, JointVector, ModelData, Robot};
use serde::Serialize;

use microrobot_supervisor::instance;
use microrobot_supervisor::monitor::StatusMonitor;
use microrobot_supervisor::summary::{HopBudget, HopStats, lifecycle_name};

/// Options of `microrobot top`.
#[derive(Debug, clap::Args)]
pub struct TopArgs {
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Print one table (or JSON object) and exit.
    #[arg(long)]
    pub once: bool,
    /// JSON output (one object per refresh).
    #[arg(long)]
    pub json: bool,
    /// Refresh period in s.
    #[arg(long, default_value_t = 1.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub interval: f64,
    /// Give up if no service reports within this many seconds.
    #[arg(long, default_value_t = 5.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub timeout: f64,
}

/// One row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub service: &'static str,
    pub pid: u32,
    pub lifecycle: &'static str,
    pub ready: bool,
    pub cycles: u64,
    pub cycles_per_s: Option<f64>,
    pub latency_p50_us: f64,
    pub latency_p99_us: f64,
    pub latency_max_us: f64,
    pub deadline_misses: u64,
    pub lost_messages: u64,
    pub refused_messages: u64,
    pub stale_cycles: u64,
    pub faults: u64,
    /// Planner: e-stops executed, and receipt → first braking setpoint of the last one
    /// (µs; null before the first e-stop and for the other services).
    pub estops: u64,
    pub estop_latency_us: Option<f64>,
    pub motion_time_s: f64,
    pub cpu_time_ms: u32,
    pub rss_kib: u64,
    /// Seconds since this service's last status arrived.
    pub age_s: f64,
    /// `ok`, `silent` (no status for over a second, process alive: hung?) or `gone`.
    pub health: &'static str,
    /// The lifecycle hook the service's last status says it is inside (`on_reset`, …;
    /// null when none): its cycle is blocked, and it stays silent, for up to
    /// `hook_budget_ms`.
    pub hook: Option<&'static str>,
    pub hook_budget_ms: Option<u32>,
    /// What `latency_*` measures for this service.
    pub latency_is: &'static str,
}

/// What the arm does, from the planner's status and the state and torque streams.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Arm {
    pub activity: String,
    pub program: String,
    pub program_time_s: f64,
    /// Joint names (from the instance's robot, else j1..jn).
    pub joints: Vec<String>,
    /// Measured positions in the unit shown beside (`deg` or `mm`).
    pub q: Vec<f64>,
    pub q_units: Vec<&'static str>,
    /// Commanded torques (N·m, or N for prismatic joints).
    pub torque: Vec<f64>,
    /// Tool pose `[x, y, z, qw, qx, qy, qz]` (m, unit quaternion), as `send move --pose`
    /// takes it; null without the robot.
    pub tool_pose: Option<[f64; 7]>,
}

const ORDER: [ServiceRole; 3] = [
    ServiceRole::Planner,
    ServiceRole::Dynamics,
    ServiceRole::Actuator,
];

fn rows(monitor: &StatusMonitor) -> Vec<Row> {
    ORDER
        .into_iter()
        .filter_map(|role| {
            let seen = monitor.latest[microrobot_supervisor::monitor::slot(role)]?;
            Some(row(
                role,
                &seen.status,
                seen.at.elapsed().as_secs_f64(),
                monitor.rate(role),
            ))
        })
        .collect()
}

/// The lifecycle hook `st` announces and its budget in ms (`None`: no hook, or one this
/// build does not know).
fn announced_hook(st: &ServiceStatus) -> Option<(LifecycleHook, u32)> {
    match LifecycleHook::from_wire(st.hook)? {
        LifecycleHook::None => None,
        hook => Some((hook, st.hook_budget_ms)),
    }
}

/// The row of `role` whose last status `st` arrived `age_s` ago.
fn row(role: ServiceRole, st: &ServiceStatus, age_s: f64, cycles_per_s: Option<f64>) -> Row {
    let us = |ns: u64| ns as f64 / 1000.0;
    // SAFETY: kill with signal 0 only checks that the process exists.
    let alive = unsafe { libc::kill(st.pid as i32, 0) } == 0;
    let health = if age_s <= 1.0 {
        "ok"
    } else if alive && st.lifecycle != microrobot_messages::LifecycleState::Finalized as u32 {
        "silent"
    } else {
        "gone"
    };
    let hook = announced_hook(st);
    Row {
        service: role.name(),
        pid: st.pid,
        lifecycle: lifecycle_name(st.lifecycle),
        ready: st.ready == 1,
        cycles: st.cycles,
        cycles_per_s,
        latency_p50_us: us(st.latency.p50_ns),
        latency_p99_us: us(st.latency.p99_ns),
        latency_max_us: us(st.latency.max_ns),
        deadline_misses: st.deadline_misses,
        lost_messages: st.lost_messages,
        refused_messages: st.refused_messages,
        stale_cycles: st.stale_cycles,
        faults: st.faults,
        estops: st.estops,
        estop_latency_us: (st.estop_latency_ns > 0).then(|| us(st.estop_latency_ns)),
        motion_time_s: st.motion_time_s,
        cpu_time_ms: st.cpu_time_ms,
        rss_kib: st.rss_kib,
        age_s,
        health,
        hook: hook.map(|(h, _)| h.name()),
        hook_budget_ms: hook.map(|(_, ms)| ms),
        latency_is: match role {
            ServiceRole::Planner => "wake-up lateness",
            ServiceRole::Dynamics => "setpoint → torque",
            ServiceRole::Actuator => "end-to-end latency",
        },
    }
}

fn table(instance: &str, rows: &[Row], arm: Option<&Arm>) -> String {
    let mut s = format!(
        "microrobot top — instance `{instance}`\n{:<9} {:>7} {:<11} {:>9} {:>9} {:>9} {:>7} {:>6} {:>7} {:>6} {:>6} {:>9} {:>11}  timing measured\n",
        "service",
        "pid",
        "lifecycle",
        "cycles/s",
        "p50 µs",
        "p99 µs",
        "misses",
        "lost",
        "refused",
        "stale",
        "faults",
        "time s",
        "e-stop µs"
    );
    for r in rows {
        let rate = r
            .cycles_per_s
            .map(|v| format!("{v:.0}"))
            .unwrap_or_else(|| "-".into());
        let hook = match (r.hook, r.hook_budget_ms) {
            (Some(h), Some(ms)) => format!("  in {h} (budget {ms} ms)"),
            _ => String::new(),
        };
        // Inside an announced hook, silence within its budget is expected.
        let within_hook = r
            .hook_budget_ms
            .is_some_and(|ms| r.age_s * 1e3 <= f64::from(ms));
        let mark = match r.health {
            "silent" if within_hook => format!(" silent {:.1} s", r.age_s),
            "silent" => format!(" SILENT {:.1} s (hung?)", r.age_s),
            "gone" => format!(" gone ({:.1} s ago)", r.age_s),
            _ => String::new(),
        };
        let estop = r
            .estop_latency_us
            .map(|v| format!("{v:.1}"))
            .unwrap_or_else(|| "-".into());
        s.push_str(&format!(
            "{:<9} {:>7} {:<11} {:>9} {:>9.1} {:>9.1} {:>7} {:>6} {:>7} {:>6} {:>6} {:>9.2} {:>11}  {}{hook}{mark}\n",
            r.service,
            r.pid,
            r.lifecycle,
            rate,
            r.latency_p50_us,
            r.latency_p99_us,
            r.deadline_misses,
            r.lost_messages,
            r.refused_messages,
            r.stale_cycles,
            r.faults,
            r.motion_time_s,
            estop,
            r.latency_is,
        ));
    }
    if let Some(a) = arm {
        s.push_str(&format!(
            "\narm: {} | program {} at {:.2} s\n",
            a.activity, a.program, a.program_time_s
        ));
        s.push_str(&format!("{:<10} {:>12} {:>12}\n", "joint", "q", "torque"));
        for (i, name) in a.joints.iter().enumerate() {
            let q =
                a.q.get(i)
                    .map(|v| format!("{v:.3} {}", a.q_units.get(i).copied().unwrap_or("")))
                    .unwrap_or_else(|| "-".into());
            let t = a
                .torque
                .get(i)
                .map(|v| format!("{v:.3}"))
                .unwrap_or_else(|| "-".into());
            s.push_str(&format!("{name:<10} {q:>12} {t:>12}\n"));
        }
        if let Some(p) = a.tool_pose {
            s.push_str(&format!(
                "tool: x {:.2} y {:.2} z {:.2} mm, q (w x y z) {:.4} {:.4} {:.4} {:.4}\n",
                p[0] * 1e3,
                p[1] * 1e3,
                p[2] * 1e3,
                p[3],
                p[4],
                p[5],
                p[6]
            ));
        }
    }
    s
}

/// The latency budget by hop from the three services' latest statuses (each counts
/// since its own start), with the end-to-end row; `None` until all three have reported.
fn hop_budget(monitor: &StatusMonitor) -> Option<(HopBudget, HopStats)> {
    let planner = monitor.get(ServiceRole::Planner)?;
    let dynamics = monitor.get(ServiceRole::Dynamics)?;
    let actuator = monitor.get(ServiceRole::Actuator)?;
    Some((
        HopBudget::from_statuses(planner, dynamics, actuator),
        HopStats::end_to_end(actuator),
    ))
}

/// The latest measured state and torque of an instance, and its robot (for joint names,
/// units and the tool pose), read from the run's resolved config when there is one.
struct ArmTap {
    _node: Node<ipc::Service>,
    state: Subscriber<ipc::Service, JointState, ()>,
    torque: Subscriber<ipc::Service, TorqueCommand, ()>,
    last_state: Option<JointState>,
    last_torque: Option<TorqueCommand>,
    robot: Option<(Robot, ModelData)>,
}

impl ArmTap {
    fn open(instance: &str) -> anyhow::Result<Self> {
        let node = microrobot_runtime::node::named_node(&format!(
            "microrobot-top-arm.{instance}.{}",
            std::process::id()
        ))?;
        let state = open_publish_subscribe::<JointState>(&node, instance, ServiceKind::State)?
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("state subscriber: {e:?}"))?;
        let torque = open_publish_subscribe::<TorqueCommand>(&node, instance, ServiceKind::Torque)?
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("torque subscriber: {e:?}"))?;
        let robot = instance::run_file(instance, "pipeline.resolved.toml")
            .ok()
            .and_then(|resolved| microrobot_config::load(&resolved).ok())
            .and_then(|cfg| Robot::from_file(&cfg.robot).ok())
            .map(|r| {
                let data = ModelData::new(&r);
                (r, data)
            });
        Ok(Self {
            _node: node,
            state,
            torque,
            last_state: None,
            last_torque: None,
            robot,
        })
    }

    fn poll(&mut self) {
        while let Ok(Some(s)) = self.state.receive() {
            self.last_state = Some(*s);
        }
        while let Ok(Some(t)) = self.torque.receive() {
            self.last_torque = Some(*t);
        }
    }

    fn arm(&mut self, planner: Option<&ServiceStatus>) -> Arm {
        let mut a = Arm::default();
        if let Some(p) = planner {
            a.activity = Activity::from_wire(p.activity)
                .map_or("unknown", Activity::name)
                .to_string();
            a.program = ProgramState::from_wire(p.program_state)
                .map_or("unknown", ProgramState::name)
                .to_string();
            a.program_time_s = p.motion_time_s;
        }
        let dof = self
            .last_state
            .map_or(0, |s| (s.dof as usize).min(MAX_JOINTS));
        for i in 0..dof {
            let kind = self
                .robot
                .as_ref()
                .and_then(|(r, _)| r.joints().get(i))
                .map(|j| (j.name.clone(), j.kind));
            let (name, kind) = kind.unwrap_or((format!("j{}", i + 1), JointKind::Revolute));
            let q = self.last_state.map_or(0.0, |s| s.q[i]);
            a.joints.push(name);
            match kind {
                JointKind::Revolute => {
                    a.q.push(q.to_degrees());
                    a.q_units.push("deg");
                }
                JointKind::Prismatic => {
                    a.q.push(q * 1e3);
                    a.q_units.push("mm");
                }
            }
            if let Some(t) = self.last_torque {
                a.torque.push(t.tau[i]);
            }
        }
        if let (Some((robot, data)), Some(st)) = (self.robot.as_mut(), self.last_state)
            && st.dof as usize == robot.dof()
        {
            let mut q = JointVector::zeros();
            for i in 0..robot.dof() {
                q[i] = st.q[i];
            }
            let iso = microrobot_model::tool_pose(robot, data, &q).to_isometry();
            let (t, r) = (iso.translation.vector, iso.rotation);
            a.tool_pose = Some([t.x, t.y, t.z, r.w, r.i, r.j, r.k]);
        }
        a
    }
}

/// Whether the pipeline has ended: every service that reported has sent its final
/// status, or none has reported for `silence`.
fn ended(monitor: &StatusMonitor, silence: Duration) -> bool {
    let seen: Vec<_> = monitor.latest.iter().flatten().collect();
    !seen.is_empty()
        && (seen
            .iter()
            .all(|s| s.status.lifecycle == microrobot_messages::LifecycleState::Finalized as u32)
            || seen.iter().all(|s| s.at.elapsed() > silence))
}

/// Shows the view until Ctrl-C or the pipeline's end (or once).
pub fn main(args: TopArgs) -> anyhow::Result<()> {
    ensure!(
        args.interval.is_finite() && args.interval >= 0.1,
        "--interval {}: must be at least 0.1 s",
        args.interval
    );
    ensure!(
        args.timeout.is_finite() && args.timeout > 0.0,
        "--timeout {}: must be a positive number of seconds",
        args.timeout
    );
    if instance::live_nodes(&args.instance).is_empty() {
        anyhow::bail!(
            "no pipeline instance `{}` is running (see `microrobot list`; start one with `microrobot run --instance {}`)",
            args.instance,
            args.instance
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let flag = stop.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))?;
    }
    let mut monitor = StatusMonitor::open(
        &args.instance,
        &format!("microrobot-top.{}.{}", args.instance, std::process::id()),
    )?;
    let mut arm = ArmTap::open(&args.instance)?;
    // First contact: something must report.
    let got = monitor.wait_for(Duration::from_secs_f64(args.timeout), |m| {
        m.latest.iter().any(Option::is_some)
    })?;
    ensure!(
        got,
        "no status from pipeline `{}` within {:.1} s: is it running? (`microrobot run --instance {}`)",
        args.instance,
        args.timeout,
        args.instance
    );
    // Every service reports at ~10 Hz: within a second all three are seen, twice
    // each (two statuses give a rate). A missing one shows as absent.
    let _ = monitor.wait_for(Duration::from_millis(1500), |m| {
        m.latest.iter().all(Option::is_some) && m.previous.iter().all(Option::is_some)
    })?;
    let clear = !args.json && !args.once && std::io::stdout().is_terminal();
    let silence = Duration::from_secs_f64(args.timeout.max(3.0));
    loop {
        monitor.poll()?;
        arm.poll();
        let rows = rows(&monitor);
        let view = arm.arm(monitor.get(ServiceRole::Planner));
        let hops = hop_budget(&monitor);
        if args.json {
            let hops = hops
                .map(|(budget, e2e)| serde_json::json!({ "hops": budget, "end_to_end_us": e2e }));
            let obj = serde_json::json!({
                "instance": args.instance, "services": rows, "arm": view, "latency_by_hop": hops
            });
            println!("{obj}");
        } else {
            if clear {
                print!("\x1b[H\x1b[2J");
            }
            let mut out = table(&args.instance, &rows, Some(&view));
            if let Some((budget, e2e)) = hops {
                out.push_str("since each service started:\n");
                budget.render(&e2e, &mut out);
            }
            print!("{out}");
        }
        if args.once || stop.load(Ordering::SeqCst) {
            return Ok(());
        }
        if ended(&monitor, silence) {
            println!("pipeline `{}` ended", args.instance);
            return Ok(());
        }
        let next = Instant::now() + Duration::from_secs_f64(args.interval);
        while Instant::now() < next {
            if stop.load(Ordering::SeqCst) {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn actuator(hook: LifecycleHook, budget_ms: u32) -> ServiceStatus {
        ServiceStatus {
            role: ServiceRole::Actuator as u32,
            lifecycle: microrobot_messages::LifecycleState::Active as u32,
            // A live process: this one.
            pid: std::process::id(),
            ready: 1,
            hook: hook as u32,
            hook_budget_ms: budget_ms,
            ..Default::default()
        }
    }

    fn rendered(st: &ServiceStatus, age_s: f64) -> (Row, String) {
        let r = row(ServiceRole::Actuator, st, age_s, None);
        let t = table("t", std::slice::from_ref(&r), None);
        let line = t
            .lines()
            .find(|l| l.starts_with("actuator"))
            .expect("an actuator row")
            .to_string();
        (r, line)
    }

    #[test]
    fn a_row_shows_the_hook_its_status_announces_with_the_budget() {
        let (r, line) = rendered(&actuator(LifecycleHook::Reset, 5000), 0.2);
        assert_eq!((r.hook, r.hook_budget_ms), (Some("on_reset"), Some(5000)));
        assert!(line.contains("in on_reset (budget 5000 ms)"), "{line}");
        // Silent inside the hook, within its budget: not taken for hung ...
        let (r, line) = rendered(&actuator(LifecycleHook::Activate, 5000), 2.5);
        assert_eq!(r.health, "silent");
        assert!(
            line.contains("in on_activate (budget 5000 ms) silent 2.5 s"),
            "{line}"
        );
        assert!(!line.contains("hung?"), "{line}");
        // ... beyond it, it is.
        let (_, line) = rendered(&actuator(LifecycleHook::Activate, 5000), 6.0);
        assert!(line.contains("SILENT 6.0 s (hung?)"), "{line}");
    }

    #[test]
    fn a_row_without_a_hook_shows_none() {
        for hook in [0, 99] {
            let st = ServiceStatus {
                hook,
                hook_budget_ms: 5000,
                ..actuator(LifecycleHook::None, 0)
            };
            let (r, line) = rendered(&st, 2.5);
            assert_eq!((r.hook, r.hook_budget_ms), (None, None));
            assert!(!line.contains("budget"), "{line}");
            assert!(line.contains("SILENT 2.5 s (hung?)"), "{line}");
        }
        let json =
            serde_json::to_value(rendered(&actuator(LifecycleHook::None, 0), 0.1).0).expect("json");
        assert!(
            json["hook"].is_null() && json["hook_budget_ms"].is_null(),
            "{json}"
        );
    }
}
