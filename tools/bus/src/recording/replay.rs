//! `microrobot replay FILE.mcap`: feeds a recording's setpoints through the dynamics
//! service's own torque law ([`microrobot_dynamics::DynamicsCore`], in-process, no IPC)
//! and checks that every torque comes out bit for bit as recorded.
//!
//! For each recorded setpoint (in sequence order) the measured state that the recorded
//! torque names by `state_seq` is handed to the core first (as the service would have
//! received it), then the setpoint is computed with "now" = the recorded torque's stamp
//! (the service's clock read happens a few µs before that stamp; it only matters for the
//! staleness checks of a free-running run). Compared: τ of the active joints (bits),
//! `flags` and `state_seq`; a setpoint the replay refuses but the run did not (or the
//! other way round) is a difference too. Config: `--config`, else the resolved config
//! attached to the recording, else `config/pipeline.toml`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, anyhow, bail};
use microrobot_dynamics::{DynamicsConfig, DynamicsCore};
use microrobot_messages::{JointSetpoint, JointState, MAX_JOINTS, TorqueCommand};
use microrobot_model::Robot;
use microrobot_runtime::PipelineConfig;
use microrobot_runtime::config::OwnedSection as _;
use serde::Serialize;

use super::closed_loop::{
    ClosedLoop, first_difference, setpoint_content, state_content, torque_content,
};
use super::{CONFIG_ATTACHMENT, Recording, setpoint_from, state_from, torque_from};

/// Options of `microrobot replay`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// Recording made by `microrobot record`.
    #[arg(value_name = "FILE.mcap")]
    pub file: PathBuf,
    /// Pipeline config (default: the one attached to the recording, else config/pipeline.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Re-run the whole lockstep loop in process (planner, dynamics and simulated arm,
    /// no IPC) and compare every recorded setpoint, torque and state bit for bit.
    #[arg(long)]
    pub closed_loop: bool,
}

/// Outcome of a replay (printed as one JSON line on stdout).
#[derive(Debug, Clone, Default, Serialize)]
pub struct ReplayReport {
    pub file: String,
    /// Where the config came from.
    pub config: String,
    /// Setpoints whose torque was recomputed and compared.
    pub compared: u64,
    /// Setpoints neither the run nor the replay gave a torque for (both refused).
    pub refused_by_both: u64,
    /// Setpoints that could not be checked: no recorded torque for them, or the state
    /// their torque used is missing from the recording.
    pub unverifiable: u64,
    pub differences: u64,
    pub identical: bool,
    /// The first difference, in words.
    pub first_difference: Option<String>,
}

fn load_config(args: &ReplayArgs, rec: &Recording) -> Result<(PipelineConfig, String)> {
    if let Some(path) = &args.config {
        let cfg = microrobot_config::load(path).map_err(anyhow::Error::new)?;
        return Ok((cfg, path.display().to_string()));
    }
    if let Some(data) = rec.attachments.get(CONFIG_ATTACHMENT) {
        let origin = format!("{} (attachment {CONFIG_ATTACHMENT})", args.file.display());
        let text = std::str::from_utf8(data)
            .map_err(|_| anyhow!("{origin}: not UTF-8 text; pass --config"))?;
        let cfg = microrobot_config::from_toml_str(text, &origin, Path::new("."))
            .map_err(anyhow::Error::new)
            .context("the attached config does not load here; pass --config")?;
        return Ok((cfg, origin));
    }
    let path = PathBuf::from("config/pipeline.toml");
    let cfg = microrobot_config::load(&path).map_err(anyhow::Error::new)?;
    Ok((cfg, path.display().to_string()))
}

fn describe_diff(sp: &JointSetpoint, rec: &TorqueCommand, got: &TorqueCommand) -> Option<String> {
    let n = (rec.dof as usize).min(MAX_JOINTS);
    for j in 0..n {
        if rec.tau[j].to_bits() != got.tau[j].to_bits() {
            return Some(format!(
                "setpoint seq {} (tick {}): joint {} torque recorded {:e} N·m, replay {:e} N·m",
                sp.header.seq,
                sp.header.tick,
                j + 1,
                rec.tau[j],
                got.tau[j]
            ));
        }
    }
    if rec.flags != got.flags || rec.state_seq != got.state_seq {
        return Some(format!(
            "setpoint seq {} (tick {}): recorded flags {} state_seq {}, replay flags {} state_seq {}",
            sp.header.seq, sp.header.tick, rec.flags, rec.state_seq, got.flags, got.state_seq
        ));
    }
    None
}

/// Replays `args.file`; the report says whether every torque was reproduced.
pub fn replay(args: &ReplayArgs) -> Result<ReplayReport> {
    let file = &args.file;
    let rec = Recording::read(file)?;
    if let Some(cut) = &rec.cut {
        eprintln!(
            "warning: {}: {cut}; replaying what was read",
            file.display()
        );
    }
    let mut setpoints = rec.parse(file, "setpoint", setpoint_from)?;
    let torques = rec.parse(file, "torque", torque_from)?;
    let states = rec.parse(file, "state", state_from)?;
    if setpoints.is_empty() {
        bail!("{}: no `setpoint` messages recorded", file.display());
    }
    if torques.is_empty() {
        bail!("{}: no `torque` messages recorded", file.display());
    }
    let (cfg, origin) = load_config(args, &rec)?;
    let robot = Robot::from_file(&cfg.robot)
        .map_err(|e| anyhow!("robot file {}: {e}", cfg.robot.display()))?;
    setpoints.sort_by_key(|s| s.header.seq);
    let by_setpoint: HashMap<u64, &TorqueCommand> =
        torques.iter().map(|t| (t.setpoint_seq, t)).collect();
    let state_by_seq: HashMap<u64, &JointState> =
        states.iter().map(|s| (s.header.seq, s)).collect();

    // One publisher id per stream, as a single planner and actuator give.
    const PUBLISHER: u128 = 1;
    let mut core = DynamicsCore::new(&robot, &cfg, &DynamicsConfig::from_pipeline(&cfg)?);
    let mut fed: Option<u64> = None;
    let mut report = ReplayReport {
        file: file.display().to_string(),
        config: origin,
        ..Default::default()
    };
    for sp in &setpoints {
        let recorded = by_setpoint.get(&sp.header.seq).copied();
        if let Some(t) = recorded
            && t.state_seq != u64::MAX
            && fed != Some(t.state_seq)
        {
            match state_by_seq.get(&t.state_seq) {
                Some(s) => {
                    let _ = core.accept_state(s, PUBLISHER, 0);
                    fed = Some(t.state_seq);
                }
                None => {
                    report.unverifiable += 1;
                    continue;
                }
            }
        }
        let now = recorded.map_or(sp.header.stamp_ns, |t| t.header.stamp_ns);
        let got = core.compute(sp, PUBLISHER, now);
        let diff = match (recorded, &got) {
            (Some(r), Ok(g)) => {
                report.compared += 1;
                describe_diff(sp, r, g)
            }
            (Some(_), Err(e)) => {
                report.compared += 1;
                Some(format!(
                    "setpoint seq {} (tick {}): the run gave a torque, the replay refused it ({e:?})",
                    sp.header.seq, sp.header.tick
                ))
            }
            (None, Err(_)) => {
                report.refused_by_both += 1;
                None
            }
            (None, Ok(_)) => {
                report.unverifiable += 1;
                None
            }
        };
        if let Some(d) = diff {
            report.differences += 1;
            report.first_difference.get_or_insert(d);
        }
    }
    report.identical = report.differences == 0 && report.compared > 0;
    Ok(report)
}

/// Outcome of a closed-loop replay (printed as one JSON line on stdout).
#[derive(Debug, Clone, Default, Serialize)]
pub struct ClosedLoopReport {
    pub file: String,
    /// Where the config came from.
    pub config: String,
    /// Ticks the in-process loop ran.
    pub ticks: u64,
    /// Recorded messages compared, per stream.
    pub setpoints: u64,
    pub torques: u64,
    pub states: u64,
    /// Recorded messages the replay differs from or never produced.
    pub differences: u64,
    pub identical: bool,
    /// The first difference, in words.
    pub first_difference: Option<String>,
}

/// Runs the recording's lockstep loop in process ([`ClosedLoop`]) and compares every
/// recorded message with the replay's message of the same sequence number.
pub fn replay_closed_loop(args: &ReplayArgs) -> Result<ClosedLoopReport> {
    let file = &args.file;
    let rec = Recording::read(file)?;
    if let Some(cut) = &rec.cut {
        eprintln!(
            "warning: {}: {cut}; replaying what was read",
            file.display()
        );
    }
    let by_seq = |v: Vec<(u64, Vec<(String, u64)>)>| v.into_iter().collect::<HashMap<_, _>>();
    let setpoints = rec.parse(file, "setpoint", setpoint_from)?;
    let torques = rec.parse(file, "torque", torque_from)?;
    let states = rec.parse(file, "state", state_from)?;
    if setpoints.is_empty() || torques.is_empty() || states.is_empty() {
        bail!(
            "{}: a closed-loop replay needs recorded `setpoint`, `torque` and `state` messages",
            file.display()
        );
    }
    let mut sp = by_seq(
        setpoints
            .iter()
            .map(|m| (m.header.seq, setpoint_content(m)))
            .collect(),
    );
    let mut tq = by_seq(
        torques
            .iter()
            .map(|m| (m.header.seq, torque_content(m)))
            .collect(),
    );
    // The actuator's shutdown state (its backend deactivated at the stop, after the
    // loop) has no counterpart in the replayed loop.
    let shutdown = |m: &&JointState| {
        m.header.seq > 1 && m.lifecycle == microrobot_messages::LifecycleState::Inactive as u32
    };
    let mut st = by_seq(
        states
            .iter()
            .filter(|m| !shutdown(m))
            .map(|m| (m.header.seq, state_content(m)))
            .collect(),
    );
    let (cfg, origin) = load_config(args, &rec)?;
    let mut sim = ClosedLoop::new(&cfg)?;
    let mut report = ClosedLoopReport {
        file: file.display().to_string(),
        config: origin,
        ..Default::default()
    };
    let note = |report: &mut ClosedLoopReport, d: Option<String>| {
        if let Some(d) = d {
            report.differences += 1;
            report.first_difference.get_or_insert(d);
        }
    };
    let check = |map: &mut HashMap<u64, Vec<(String, u64)>>,
                 what: &str,
                 seq: u64,
                 got: Vec<(String, u64)>,
                 n: &mut u64|
     -> Option<String> {
        let recorded = map.remove(&seq)?;
        *n += 1;
        first_difference(&format!("{what} seq {seq}"), &recorded, &got)
    };
    let s0 = sim.initial_state();
    let d = check(
        &mut st,
        "state",
        s0.header.seq,
        state_content(&s0),
        &mut report.states,
    );
    note(&mut report, d);
    // Every recorded message has a sequence number no larger than the loop's tick count
    // (+1 for the initial state); a few spare ticks would show a late one.
    let last = [&sp, &tq, &st]
        .iter()
        .filter_map(|m| m.keys().max().copied())
        .max()
        .unwrap_or(0);
    while report.ticks <= last && !(sp.is_empty() && tq.is_empty() && st.is_empty()) {
        let out = sim.tick();
        report.ticks += 1;
        let seq = out.setpoint.header.seq;
        let d = check(
            &mut sp,
            "setpoint",
            seq,
            setpoint_content(&out.setpoint),
            &mut report.setpoints,
        );
        note(&mut report, d);
        if let Some(t) = &out.torque {
            let d = check(
                &mut tq,
                "torque",
                t.header.seq,
                torque_content(t),
                &mut report.torques,
            );
            note(&mut report, d);
        }
        let d = check(
            &mut st,
            "state",
            out.state.header.seq,
            state_content(&out.state),
            &mut report.states,
        );
        note(&mut report, d);
    }
    for (what, left) in [("setpoint", &sp), ("torque", &tq), ("state", &st)] {
        if let Some(seq) = left.keys().min() {
            let d = Some(format!(
                "{what} seq {seq}: recorded, but the replay never produced it ({} such {what}s)",
                left.len()
            ));
            report.differences += left.len() as u64 - 1;
            note(&mut report, d);
        }
    }
    report.identical = report.differences == 0 && report.torques > 0;
    Ok(report)
}

/// Runs `microrobot replay`: exit 0 only when every compared message is bit-identical.
pub fn main(args: ReplayArgs) -> Result<()> {
    if args.closed_loop {
        let report = replay_closed_loop(&args)?;
        println!(
            "{}",
            serde_json::to_string(&report).context("cannot serialise the report")?
        );
        if let Some(d) = &report.first_difference {
            bail!(
                "closed-loop replay differs from the recording in {} messages; first: {d}",
                report.differences
            );
        }
        eprintln!(
            "replay: {} setpoints, {} torques and {} states bit-identical to the in-process loop ({} ticks, config {})",
            report.setpoints, report.torques, report.states, report.ticks, report.config
        );
        return Ok(());
    }
    let report = replay(&args)?;
    println!(
        "{}",
        serde_json::to_string(&report).context("cannot serialise the report")?
    );
    if report.compared == 0 {
        bail!(
            "{}: no recorded torque matches a recorded setpoint: nothing to compare",
            args.file.display()
        );
    }
    if let Some(d) = &report.first_difference {
        return Err(microrobot_command_line::exit::with_code(
            microrobot_runtime::exit_code::JOB_FAILED,
        )(anyhow::anyhow!(
            "replay differs from the recording in {} of {} torques; first: {d}",
            report.differences,
            report.compared
        )));
    }
    eprintln!(
        "replay: all {} torques bit-identical ({} unverifiable, config {})",
        report.compared, report.unverifiable, report.config
    );
    Ok(())
}
