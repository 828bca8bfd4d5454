//! `microrobot`: the user-facing command line of the microrobot motion stack.
//!
//! One binary for everything a user does: run and supervise the pipeline, command and
//! watch a running one, and evaluate the models offline. The pipeline's services are
//! separate processes: the supervisor starts the slim service binaries of the same build
//! (`microrobot-planner`, `microrobot-dynamics`, `microrobot-actuator`) found beside this one.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::LazyLock;

use clap::{Parser, Subcommand};
use microrobot_bus_tools::recording::{export, plot, record, recover, replay};
use microrobot_bus_tools::{inspect, send, teleop_report, teleop_source, top};
use microrobot_soak::{self as soak, probe_chain};
use microrobot_study::{self as study, eval_model, eval_trajectory, robot_cmd};
use microrobot_supervisor::{binaries, check, driver_check, run};

/// `--version`: the package version and the build id.
static VERSION: LazyLock<String> = LazyLock::new(|| {
    format!(
        "{} (build {})",
        env!("CARGO_PKG_VERSION"),
        microrobot_build_id::BUILD_ID
    )
});

#[derive(Parser)]
#[command(
    name = "microrobot",
    version = VERSION.as_str(),
    about = "Real-time motion stack for a 6-DOF surgical arm"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Start the planner, dynamics and actuator processes headless and supervise them.
    Run(run::RunArgs),
    /// Check the pipeline config, robot and program together before anything moves, and
    /// print the resolved settings.
    Check(check::CheckArgs),
    /// Run an actuator driver (any language) against a scripted pipeline and check the
    /// driver contract clause by clause.
    DriverCheck(driver_check::DriverCheckArgs),
    /// Run the pipeline for minutes to hours with injected faults and write a soak report.
    Soak(soak::SoakArgs),
    /// Measure the machine's floor for the pipeline's latency and CPU: three bare processes
    /// with the pipeline's bus hops and real-time settings, and no work.
    ProbeChain(probe_chain::ProbeChainArgs),
    /// Send a motion command (move, stop, estop, reset) to a running pipeline.
    Send(send::SendArgs),
    /// Show live rates, latencies and health of a running pipeline.
    Top(top::TopArgs),
    /// List pipeline instances: running ones with robot, rate and uptime, and stale run
    /// directories.
    List(inspect::ListArgs),
    /// Print each message of a stream of a running pipeline as a JSON line.
    Echo(inspect::EchoArgs),
    /// Measure the rate of a stream of a running pipeline (from the publishers' stamps).
    Hz(inspect::HzArgs),
    /// Print a service's log of an instance's last run (`--follow` to keep reading).
    Logs(inspect::LogsArgs),
    /// Stand in for a master device: publish a synthetic or recorded hand motion.
    TeleopSource(teleop_source::TeleopSourceArgs),
    /// Tremor attenuation, scaling error, latency and tracking of a teleop pipeline.
    TeleopReport(teleop_report::TeleopReportArgs),
    /// Regenerate the seed's study (tables, workspace, Jacobian, trajectories, torques, verdicts).
    Study(study::StudyArgs),
    /// Record every stream of a running pipeline to an MCAP file (JSON, Foxglove-ready).
    Record(record::RecordArgs),
    /// Serve a live Foxglove WebSocket view of a running pipeline (ws://127.0.0.1:8765 by
    /// default; `microrobot view --help` for its options). Runs `microrobot-view`, found
    /// beside this executable.
    #[command(disable_help_flag = true)]
    View {
        /// The options of `microrobot-view` (`--instance NAME`, `--bind ADDR:PORT`,
        /// `--transforms-hz HZ`, `--joints-hz HZ`).
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
        args: Vec<OsString>,
    },
    /// Write one CSV per topic of a recording.
    Export(export::ExportArgs),
    /// Draw torque, tracking error and latency of a recording as PNGs.
    Plot(plot::PlotArgs),
    /// Recompute a recording's torques with the dynamics law and check they are bit-identical.
    Replay(replay::ReplayArgs),
    /// Write a finished, indexed copy of a recording that ended early (a recorder killed,
    /// a full disk): everything up to its last complete chunk.
    Recover(recover::RecoverArgs),
    /// Evaluate a model or a trajectory: JSON lines in on stdin, JSON lines out on stdout.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Convert a robot description (`robot urdf`: any robot file as URDF and its overlay).
    #[command(subcommand)]
    Robot(robot_cmd::RobotCommand),
    /// Print a shell completion script (e.g. `microrobot completions bash >
    /// ~/.local/share/bash-completion/completions/microrobot`).
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
}

/// The input and output of `eval model`, shown by `--help`.
const EVAL_MODEL_SCHEMA: &str = "\
Input: one JSON object per line on stdin, SI units (rad, or m for prismatic joints):
  {\"q\": [q1, ..., qn], \"qd\": [...], \"qdd\": [...]}        (n = the robot's joint count)
Output: one JSON object per input line, in order, flushed per line:
  {\"fk\": 4x4 tool pose (row-major, m), \"tool_pose\": [x, y, z, qw, qx, qy, qz],
   \"jacobian\": 6 x n (rows vx vy vz wx wy wz), \"mass_matrix\": n x n,
   \"gravity_torque\": [n], \"coriolis_torque\": [n], \"tau\": [n]}
A bad line gets {\"error\": \"line N: ...\"} and the rest go on; the exit code is then 7.
Example:
  echo '{\"q\":[0,0,0,0,0,0],\"qd\":[0,0,0,0,0,0],\"qdd\":[0,0,0,0,0,0]}' | \\
    microrobot eval model --robot config/robots/seed-arm.toml";

/// The input and output of `eval trajectory`, shown by `--help`.
const EVAL_TRAJECTORY_SCHEMA: &str = "\
Input: one JSON object per line on stdin, one problem each, SI units:
  {\"profile\": \"cubic\" | \"quintic\" | \"lspb\" | \"soft\",
   \"q0\", \"q1\"                 start and target position (required)
   \"duration\"                 s; required for cubic, quintic, lspb; soft: minimum (0: time-optimal)
   \"v0\", \"v1\", \"a0\", \"a1\"     boundary velocities and accelerations (default 0)
   \"cruise_velocity\"          lspb only
   \"vmax\", \"amax\", \"jmax\"     limits (required for soft)
   \"times\": [t, ...]          sample times (s)
   \"id\"                       echoed back}
  A per-joint field may be a number or an array; with arrays the line is one synchronised
  multi-joint problem and the samples come back indexed [time][joint].
Output: one JSON object per input line, in order:
  {\"duration\", \"q\", \"qd\", \"qdd\", \"jerk\"} at the given times, or {\"error\": \"...\"} naming
  the field; the rest go on; the exit code is then 7.
Example:
  echo '{\"profile\":\"soft\",\"q0\":0,\"q1\":1,\"vmax\":1,\"amax\":2,\"jmax\":4,\"times\":[0,0.5,1]}' | \\
    microrobot eval trajectory";

#[derive(Subcommand)]
enum EvalCommand {
    /// Kinematics and dynamics of a robot file for each `{"q","qd","qdd"}` line.
    #[command(after_long_help = EVAL_MODEL_SCHEMA)]
    Model {
        /// Robot description (TOML), e.g. config/robots/seed-arm.toml.
        #[arg(long)]
        robot: PathBuf,
        /// Dynamics path for tau, mass_matrix, gravity_torque and coriolis_torque.
        #[arg(long, value_enum, default_value = "newton-euler")]
        method: eval_model::Method,
    },
    /// Sample one trajectory problem per line (cubic, quintic, lspb, soft).
    #[command(after_long_help = EVAL_TRAJECTORY_SCHEMA)]
    Trajectory,
}

/// Replaces this process with `microrobot-view ARGS` of this build (see
/// `microrobot_supervisor::binaries`); returns only on failure.
fn view(args: Vec<OsString>) -> anyhow::Result<()> {
    use std::os::unix::process::CommandExt as _;
    let path = binaries::locate_view()?;
    let err = std::process::Command::new(&path).args(args).exec();
    Err(anyhow::anyhow!("cannot run {}: {err}", path.display()))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // iceoryx2's own notices (e.g. "no config file was loaded") only on request.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    if !matches!(
        cli.command,
        Command::Run(_) | Command::Soak(_) | Command::Record(_) | Command::View { .. }
    ) {
        // A closed stdout (`| head`) ends a printing command quietly, as it does `cat`,
        // instead of a panic in println!. The supervisor and the services keep Rust's
        // default (SIGPIPE ignored): a closed pipe must never kill a pipeline.
        // SAFETY: signal(2) with SIG_DFL, before any thread is started.
        unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    }
    let result = match cli.command {
        Command::Run(args) => return run::main(args),
        Command::Check(args) => return check::main(args),
        Command::Soak(args) => return soak::main(args),
        Command::DriverCheck(args) => return driver_check::main(args),
        Command::ProbeChain(args) => probe_chain::main(args),
        Command::Send(args) => send::main(args),
        Command::Top(args) => top::main(args),
        Command::List(args) => inspect::list(args),
        Command::Echo(args) => inspect::echo(args),
        Command::Hz(args) => inspect::hz(args),
        Command::Logs(args) => inspect::logs(args),
        Command::TeleopSource(args) => teleop_source::main(args),
        Command::TeleopReport(args) => teleop_report::main(args),
        Command::Study(args) => study::main(args),
        Command::Record(args) => record::main(args),
        Command::View { args } => view(args),
        Command::Export(args) => export::main(args),
        Command::Plot(args) => plot::main(args),
        Command::Replay(args) => replay::main(args),
        Command::Recover(args) => recover::main(args),
        Command::Eval(EvalCommand::Model { robot, method }) => eval_model::run(&robot, method),
        Command::Eval(EvalCommand::Trajectory) => {
            eval_trajectory::run().map_err(eval_model::exit_code_of_refused)
        }
        Command::Robot(cmd) => robot_cmd::main(cmd),
        Command::Completions { shell } => {
            let mut cmd = <Cli as clap::CommandFactory>::command();
            clap_complete::generate(shell, &mut cmd, "microrobot", &mut std::io::stdout());
            Ok(())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(microrobot_command_line::exit::code_of(&e))
        }
    }
}
