//! `microrobot send`: one motion command (move, stop, e-stop, reset) to a running
//! pipeline's planner, validated here first, and the planner's verdict on this very
//! command reported from its status stream: the status carries the verdicts of the
//! planner's recent commands, each with the sending publisher's id and the command's
//! `seq`, so parallel senders each find their own.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail, ensure};
use iceoryx2::prelude::*;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use microrobot_messages::{
    COMMAND_VERDICTS, CommandKind, MAX_JOINTS, MotionCommand, ProfileKind, RefusalReason,
    ServiceKind, ServiceRole, TargetSpace, VerdictLookup, monotonic_ns, open_event,
    open_publish_subscribe, service_name,
};
use microrobot_model::{JointKind, Robot};

use microrobot_supervisor::monitor::StatusMonitor;

/// Options of `microrobot send`.
#[derive(Debug, clap::Args)]
pub struct SendArgs {
    /// Instance name of the running pipeline (before or after the command).
    #[arg(long, global = true, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Pipeline config whose robot checks targets before sending when the instance's
    /// own resolved config cannot be read (a running instance's robot is always the one
    /// it runs); skipped when neither exists.
    #[arg(long, global = true, default_value_os_t = microrobot_command_line::config_path::default_config(), value_name = "FILE")]
    pub config: PathBuf,
    /// How long to wait for the planner (connection and verdict).
    #[arg(long, global = true, default_value_t = 10.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub timeout: f64,
    /// `move` and `stop`: return once the arm is holding again, with the motion's duration;
    /// an error (exit 7) if the motion ends any other way (another command took over, an
    /// e-stop, a stale measured state, the actuator's safe state).
    #[arg(long, global = true)]
    pub wait: bool,
    #[command(subcommand)]
    pub command: SendCommand,
}

/// The command to send.
#[derive(Debug, clap::Subcommand)]
pub enum SendCommand {
    /// Move to a joint target or a tool pose, replanning from the current setpoint.
    Move(MoveArgs),
    /// Stop smoothly (shortest jerk-limited stop), then hold.
    Stop,
    /// Emergency stop: brake at once; motion is refused until `reset`.
    Estop,
    /// Leave e-stop (once its brake has come to rest) / the safe state (motion resumes
    /// from the measured state).
    Reset,
    /// Enter teleop mode (arm at rest): the master device drives the arm until `stop`.
    Teleop,
}

/// Trajectory profile of a move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Profile {
    /// Time-optimal jerk-limited (soft motion); `--duration` stretches it.
    Soft,
    /// Cubic polynomial over `--duration`.
    Cubic,
    /// Quintic polynomial over `--duration`.
    Quintic,
    /// Linear segments with parabolic blends over `--duration`.
    Lspb,
}

/// Target and profile of a move.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["joints", "pose"])))]
pub struct MoveArgs {
    /// Joint target, comma separated (rad and m, or deg and mm with --deg).
    #[arg(long, value_name = "Q1,Q2,...", allow_hyphen_values = true)]
    pub joints: Option<String>,
    /// Tool pose target: x,y,z (m) and a unit quaternion qw,qx,qy,qz.
    #[arg(long, value_name = "X,Y,Z,QW,QX,QY,QZ", allow_hyphen_values = true)]
    pub pose: Option<String>,
    /// --joints in degrees (revolute) and mm (prismatic).
    #[arg(long)]
    pub deg: bool,
    #[arg(long, value_enum, default_value = "soft")]
    pub profile: Profile,
    /// Duration in s (required for cubic, quintic, lspb; for soft, 0 = time-optimal).
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse_or_zero)]
    pub duration: Option<f64>,
    /// Scale (0, 1] of the robot's velocity, acceleration and jerk limits.
    #[arg(long, default_value_t = 1.0, value_name = "SCALE")]
    pub limit_scale: f64,
}

fn parse_list(text: &str, what: &str) -> anyhow::Result<Vec<f64>> {
    let values = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<f64>()
                .with_context(|| format!("{what}: `{s}` is not a number"))
        })
        .collect::<anyhow::Result<Vec<f64>>>()?;
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        bail!("{what}: {v} is not a finite number");
    }
    Ok(values)
}

/// The robot of the pipeline config, if the config file exists (so targets can be checked).
fn robot_of(config: &std::path::Path) -> anyhow::Result<Option<Robot>> {
    if !config.exists() {
        return Ok(None);
    }
    let cfg = microrobot_config::load(config).map_err(anyhow::Error::new)?;
    let robot = Robot::from_file(&cfg.robot)
        .map_err(|e| anyhow::anyhow!("{}: {e}", cfg.robot.display()))?;
    Ok(Some(robot))
}

/// Builds and validates the command (everything the planner would refuse that can be
/// known here is refused here, with a message that names it).
pub fn build_command(args: &SendArgs, robot: Option<&Robot>) -> anyhow::Result<MotionCommand> {
    let mut cmd = MotionCommand {
        seq: monotonic_ns(),
        limit_scale: 1.0,
        ..MotionCommand::default()
    };
    match &args.command {
        SendCommand::Stop => cmd.kind = CommandKind::Stop as u32,
        SendCommand::Estop => cmd.kind = CommandKind::EStop as u32,
        SendCommand::Reset => cmd.kind = CommandKind::Reset as u32,
        SendCommand::Teleop => cmd.kind = CommandKind::Teleop as u32,
        SendCommand::Move(m) => {
            cmd.kind = CommandKind::Move as u32;
            cmd.profile = match m.profile {
                Profile::Soft => ProfileKind::Soft,
                Profile::Cubic => ProfileKind::Cubic,
                Profile::Quintic => ProfileKind::Quintic,
                Profile::Lspb => ProfileKind::Lspb,
            } as u32;
            let duration = m.duration.unwrap_or(0.0);
            ensure!(
                duration.is_finite() && duration >= 0.0,
                "--duration {duration}: must be a finite number of seconds >= 0"
            );
            if m.profile != Profile::Soft {
                ensure!(
                    duration > 0.0,
                    "--profile {:?} needs --duration > 0 (s)",
                    m.profile
                );
            }
            ensure!(
                duration <= 3600.0,
                "--duration {duration}: longer than an hour is surely a mistake"
            );
            cmd.duration_s = duration;
            ensure!(
                m.limit_scale.is_finite()
                    && m.limit_scale >= microrobot_planner::MIN_LIMIT_SCALE
                    && m.limit_scale <= 1.0,
                "--limit-scale {}: must be in [0.001, 1]",
                m.limit_scale
            );
            cmd.limit_scale = m.limit_scale;
            if let Some(text) = &m.joints {
                let mut q = parse_list(text, "--joints")?;
                ensure!(
                    (1..=MAX_JOINTS).contains(&q.len()),
                    "--joints: {} values, expected 1..={MAX_JOINTS}",
                    q.len()
                );
                if let Some(robot) = robot {
                    ensure!(
                        q.len() == robot.dof(),
                        "--joints: {} values, but robot `{}` has {} joints",
                        q.len(),
                        robot.name(),
                        robot.dof()
                    );
                }
                if m.deg {
                    for (j, v) in q.iter_mut().enumerate() {
                        let prismatic =
                            robot.is_some_and(|r| r.joints()[j].kind == JointKind::Prismatic);
                        *v = if prismatic {
                            *v / 1000.0
                        } else {
                            v.to_radians()
                        };
                    }
                }
                if let Some(robot) = robot {
                    for (v, joint) in q.iter().zip(robot.joints()) {
                        let l = &joint.limits;
                        // Back in the units the user typed: deg or mm with --deg, else SI.
                        let (scale, unit) = match (m.deg, joint.kind) {
                            (true, JointKind::Revolute) => (180.0 / std::f64::consts::PI, "°"),
                            (true, JointKind::Prismatic) => (1000.0, " mm"),
                            (false, JointKind::Revolute) => (1.0, " rad"),
                            (false, JointKind::Prismatic) => (1.0, " m"),
                        };
                        let u = |x: f64| {
                            format!(
                                "{}{unit}",
                                microrobot_supervisor::check::trim_number(x * scale)
                            )
                        };
                        ensure!(
                            l.contains(*v),
                            "--joints: {} target {} is outside its range [{}, {}]",
                            joint.name,
                            u(*v),
                            u(l.min),
                            u(l.max)
                        );
                    }
                }
                cmd.space = TargetSpace::Joint as u32;
                cmd.dof = q.len() as u32;
                cmd.target[..q.len()].copy_from_slice(&q);
            } else if let Some(text) = &m.pose {
                ensure!(
                    !m.deg,
                    "--deg applies to --joints only; --pose is in m and a quaternion"
                );
                let p = parse_list(text, "--pose")?;
                ensure!(
                    p.len() == 7,
                    "--pose: {} values, expected 7 (x,y,z in m, then qw,qx,qy,qz)",
                    p.len()
                );
                let norm = p[3..7].iter().map(|v| v * v).sum::<f64>().sqrt();
                ensure!(
                    (norm - 1.0).abs() <= 1e-3,
                    "--pose: the quaternion (qw,qx,qy,qz) has norm {norm:.6}, expected a unit quaternion"
                );
                cmd.space = TargetSpace::Cartesian as u32;
                cmd.dof = robot.map_or(0, |r| r.dof() as u32);
                cmd.target[..3].copy_from_slice(&p[..3]);
                for k in 0..4 {
                    cmd.target[3 + k] = p[3 + k] / norm;
                }
            }
        }
    }
    Ok(cmd)
}

/// Sends the command and reports the planner's verdict; an error if refused.
pub fn main(args: SendArgs) -> anyhow::Result<()> {
    ensure!(
        args.timeout.is_finite() && args.timeout > 0.0,
        "--timeout {}: must be a positive number of seconds",
        args.timeout
    );
    // The robot the running instance runs, from the config its supervisor resolved.
    let running = !microrobot_supervisor::instance::live_nodes(&args.instance).is_empty();
    let resolved = if running {
        Some(microrobot_supervisor::instance::run_file(
            &args.instance,
            "pipeline.resolved.toml",
        )?)
    } else {
        None
    };
    let config = if let Some(resolved) = resolved.filter(|p| p.exists()) {
        resolved
    } else {
        args.config.clone()
    };
    ensure!(
        !args.wait || matches!(args.command, SendCommand::Move(_) | SendCommand::Stop),
        "--wait applies to `move` and `stop` (the commands that end in a hold)"
    );
    let robot = robot_of(&config)
        .with_context(|| format!("cannot check the target against {}", config.display()))?;
    let mut cmd = build_command(&args, robot.as_ref())?;
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Error);

    let instance = args.instance.as_str();
    let timeout = Duration::from_secs_f64(args.timeout);
    let name = service_name(instance, ServiceKind::Command);
    let svc_name = ServiceName::new(&name).map_err(|e| anyhow::anyhow!("{name}: {e:?}"))?;
    let exists = ipc::Service::does_exist(
        &svc_name,
        Config::global_config(),
        MessagingPattern::PublishSubscribe,
    )
    .map_err(|e| anyhow::anyhow!("cannot look up {name}: {e:?}"))?;
    ensure!(
        exists,
        "no pipeline `{instance}` is running (service {name} does not exist); start one with `microrobot run --instance {instance}`"
    );

    let mut monitor = StatusMonitor::open(
        instance,
        &format!("microrobot-send.{instance}.{}", std::process::id()),
    )?;
    let command_svc =
        open_publish_subscribe::<MotionCommand>(monitor.node(), instance, ServiceKind::Command)?;
    let publisher = command_svc
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("command publisher: {e:?}"))?;
    let notifier = open_event(monitor.node(), instance, ServiceKind::Command)?
        .notifier_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("command notifier: {e:?}"))?;

    // The planner must be subscribed (a sample sent before it subscribes is lost) and
    // have reported a status (the baseline of its accepted/refused counters).
    let end = Instant::now() + timeout;
    loop {
        monitor.poll()?;
        if command_svc.dynamic_config().number_of_subscribers() > 0
            && monitor.get(ServiceRole::Planner).is_some()
        {
            break;
        }
        ensure!(
            Instant::now() < end,
            "the planner of `{instance}` did not connect within {:.1} s",
            timeout.as_secs_f64()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    // Let a status that was already on its way arrive, then take the baseline.
    std::thread::sleep(Duration::from_millis(20));
    monitor.poll()?;
    let base = *monitor
        .get(ServiceRole::Planner)
        .context("planner status vanished")?;

    cmd.stamp_ns = monotonic_ns();
    publisher
        .send_copy(cmd)
        .map_err(|e| anyhow::anyhow!("cannot send the command: {e:?}"))?;
    let _ = notifier.notify();

    let me = publisher.id().value();
    let end = Instant::now() + timeout;
    let mut maybe_overwritten = false;
    loop {
        // Every status, not only the newest: each carries the verdicts taken until then.
        for st in monitor.poll_all()? {
            if st.role != ServiceRole::Planner as u32 {
                continue;
            }
            if st.pid != base.pid {
                bail!(
                    "the planner restarted while the command was in flight; its verdict is unknown"
                );
            }
            match st.command_verdict(me, cmd.seq, base.commands_taken()) {
                VerdictLookup::Accepted => {
                    println!(
                        "accepted by the planner of `{instance}` (command seq {})",
                        cmd.seq
                    );
                    if args.wait {
                        let newest = st.commands_taken().checked_sub(1).map(|n| {
                            st.command_verdicts
                                [(n % microrobot_messages::COMMAND_VERDICTS as u64) as usize]
                        });
                        let id = [me as u64, (me >> 64) as u64];
                        ensure!(
                            newest.is_some_and(|v| v.seq == cmd.seq && v.publisher == id),
                            "the motion did not finish: another command reached the planner right after it (its log names it)"
                        );
                        return wait_for_hold(&mut monitor, instance, &st);
                    }
                    return Ok(());
                }
                VerdictLookup::Refused(why) => {
                    let why = why.map_or("see its log for why", RefusalReason::describe);
                    // The status's limit detail is the newest refusal's: shown only when
                    // that is this command (the newest command taken is ours).
                    let newest = st.commands_taken().checked_sub(1).map(|n| {
                        &st.command_verdicts
                            [(n % microrobot_messages::COMMAND_VERDICTS as u64) as usize]
                    });
                    let id = [me as u64, (me >> 64) as u64];
                    let ours = newest.is_some_and(|v| v.seq == cmd.seq && v.publisher == id);
                    let deg = matches!(&args.command, SendCommand::Move(m) if m.deg);
                    let detail = if ours {
                        refusal_detail(&st, robot.as_ref(), deg)
                    } else {
                        String::new()
                    };
                    return Err(microrobot_command_line::exit::with_code(
                        microrobot_runtime::exit_code::JOB_FAILED,
                    )(anyhow::anyhow!(
                        "the planner of `{instance}` refused the command (seq {}): {why}{detail}",
                        cmd.seq
                    )));
                }
                VerdictLookup::MaybeOverwritten => maybe_overwritten = true,
                VerdictLookup::NotYet => {}
            }
        }
        if Instant::now() >= end {
            if maybe_overwritten {
                bail!(
                    "no verdict from the planner of `{instance}` within {:.1} s: more than {COMMAND_VERDICTS} commands reached it at once, so its status may no longer show this one (its log names every command's verdict by seq {})",
                    timeout.as_secs_f64(),
                    cmd.seq
                );
            }
            bail!(
                "no verdict from the planner of `{instance}` within {:.1} s",
                timeout.as_secs_f64()
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// How long the planner may stay silent while `--wait` waits: ten status periods of the
/// default config, far beyond a healthy planner's gap and below the supervisor's patience.
const WAIT_SILENCE: Duration = Duration::from_secs(2);

/// Where a waited-for motion stands in one planner status.
#[derive(Debug, PartialEq)]
enum WaitStep {
    /// Still moving or braking as commanded.
    Pending,
    /// Holding again after this many seconds of the planner's logical time.
    Done(f64),
    /// Ended any other way, and how.
    Failed(String),
}

/// Judges one planner status `st` against the status `accepted` that carried the
/// command's acceptance (pure, so each case is tested below).
fn wait_step(
    accepted: &microrobot_messages::ServiceStatus,
    st: &microrobot_messages::ServiceStatus,
) -> WaitStep {
    use microrobot_messages::Activity;
    if st.pid != accepted.pid {
        return WaitStep::Failed("the planner restarted".into());
    }
    let now = Activity::from_wire(st.activity);
    match now {
        Some(Activity::EStop) => return WaitStep::Failed("an e-stop is braking the arm".into()),
        Some(Activity::SafeHold) => {
            return WaitStep::Failed("the actuator latched its safe state".into());
        }
        _ => {}
    }
    if st.commands_taken() > accepted.commands_taken() {
        return WaitStep::Failed("another command reached the planner (its log names it)".into());
    }
    let commanded = Activity::from_wire(accepted.activity);
    match now {
        Some(Activity::Hold) => {
            WaitStep::Done((st.motion_time_s - accepted.motion_time_s).max(0.0))
        }
        now @ Some(Activity::Move | Activity::Stopping) if now == commanded => WaitStep::Pending,
        Some(Activity::Stopping) => WaitStep::Failed(
            "the planner is braking to rest (a stale measured state; see its log)".into(),
        ),
        other => WaitStep::Failed(format!("the planner's activity is now {other:?}")),
    }
}

/// `--wait`: follows the planner's statuses from the one that accepted the command until
/// the arm holds again (prints the motion's duration) or the motion ends otherwise (an
/// error naming how, exit 7).
fn wait_for_hold(
    monitor: &mut StatusMonitor,
    instance: &str,
    accepted: &microrobot_messages::ServiceStatus,
) -> anyhow::Result<()> {
    let failed = |why: String| {
        microrobot_command_line::exit::with_code(microrobot_runtime::exit_code::JOB_FAILED)(
            anyhow::anyhow!("the motion did not finish: {why}"),
        )
    };
    let mut last_status = Instant::now();
    let mut pending = vec![*accepted];
    loop {
        for st in pending.drain(..) {
            match wait_step(accepted, &st) {
                WaitStep::Pending => {}
                WaitStep::Done(s) => {
                    println!("done: holding after {s:.3} s of motion");
                    return Ok(());
                }
                WaitStep::Failed(why) => return Err(failed(why)),
            }
        }
        while pending.is_empty() {
            pending.extend(
                monitor
                    .poll_all()?
                    .into_iter()
                    .filter(|s| s.role == ServiceRole::Planner as u32),
            );
            if !pending.is_empty() {
                last_status = Instant::now();
            } else if last_status.elapsed() > WAIT_SILENCE {
                return Err(failed(format!(
                    "the planner of `{instance}` stopped reporting for {:.1} s",
                    WAIT_SILENCE.as_secs_f64()
                )));
            } else {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
}

/// The limit a refused command broke, from the planner's status, in the units the user
/// typed (`--deg`: degrees or mm, else rad or m), e.g. `: j2 acceleration -35.5°/s² is
/// outside [-20°/s², 20°/s²]`; empty when the refusal names no limit.
fn refusal_detail(
    st: &microrobot_messages::ServiceStatus,
    robot: Option<&Robot>,
    deg: bool,
) -> String {
    use microrobot_messages::RefusalQuantity as Q;
    let Some(q) = Q::from_wire(st.refusal_quantity).filter(|q| *q != Q::None) else {
        return String::new();
    };
    let joint = (st.refusal_joint as usize).checked_sub(1);
    let kind = joint
        .and_then(|j| robot.and_then(|r| r.joints().get(j)))
        .map_or(JointKind::Revolute, |j| j.kind);
    let name = joint.map(|j| {
        robot
            .and_then(|r| r.joints().get(j))
            .map_or(format!("joint {}", j + 1), |jt| jt.name.clone())
    });
    let (scale, base) = match (q, kind, deg) {
        (Q::Duration, _, _) => (1.0, " s"),
        (_, JointKind::Revolute, true) => (180.0 / std::f64::consts::PI, "°"),
        (_, JointKind::Prismatic, true) => (1000.0, " mm"),
        (_, JointKind::Revolute, false) => (1.0, " rad"),
        (_, JointKind::Prismatic, false) => (1.0, " m"),
    };
    let per = match q {
        Q::Velocity => "/s",
        Q::Acceleration => "/s²",
        Q::Jerk => "/s³",
        _ => "",
    };
    let u = |x: f64| {
        if x.is_infinite() {
            if x > 0.0 {
                "∞".to_string()
            } else {
                "-∞".to_string()
            }
        } else {
            format!(
                "{}{base}{per}",
                microrobot_supervisor::check::trim_number(x * scale)
            )
        }
    };
    format!(
        ": {}{} {} is outside [{}, {}]",
        name.map(|n| format!("{n} ")).unwrap_or_default(),
        q.name(),
        u(st.refusal_value),
        u(st.refusal_min),
        u(st.refusal_max)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use microrobot_messages::{Activity, ServiceStatus};

    fn status(activity: Activity, accepted: u64, motion_time_s: f64) -> ServiceStatus {
        ServiceStatus {
            pid: 7,
            activity: activity as u32,
            commands_accepted: accepted,
            motion_time_s,
            ..Default::default()
        }
    }

    #[test]
    fn a_move_is_done_when_the_planner_holds_again() {
        let accepted = status(Activity::Move, 3, 10.0);
        assert_eq!(
            wait_step(&accepted, &status(Activity::Move, 3, 11.0)),
            WaitStep::Pending
        );
        assert_eq!(
            wait_step(&accepted, &status(Activity::Hold, 3, 12.5)),
            WaitStep::Done(2.5)
        );
        let stop = status(Activity::Stopping, 4, 1.0);
        assert_eq!(
            wait_step(&stop, &status(Activity::Stopping, 4, 1.1)),
            WaitStep::Pending
        );
    }

    #[test]
    fn a_move_that_ends_any_other_way_fails_naming_how() {
        let accepted = status(Activity::Move, 3, 10.0);
        let failed = |st: ServiceStatus| match wait_step(&accepted, &st) {
            WaitStep::Failed(why) => why,
            other => panic!("{other:?}"),
        };
        assert!(failed(status(Activity::Stopping, 3, 11.0)).contains("stale measured state"));
        assert!(failed(status(Activity::EStop, 3, 11.0)).contains("e-stop"));
        assert!(failed(status(Activity::SafeHold, 3, 11.0)).contains("safe state"));
        assert!(failed(status(Activity::Hold, 4, 11.0)).contains("another command"));
        assert!(
            failed(ServiceStatus {
                pid: 8,
                ..status(Activity::Hold, 3, 11.0)
            })
            .contains("restarted")
        );
        assert!(failed(status(Activity::Teleop, 3, 11.0)).contains("Teleop"));
    }
}
