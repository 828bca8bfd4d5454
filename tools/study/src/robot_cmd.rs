//! `microrobot robot urdf FILE`: a robot (DH TOML, URDF or overlay) written as URDF, with
//! the overlay that adds what URDF cannot carry, so viewers (RViz, Foxglove) and other
//! tools (Pinocchio) load the same arm. The conversion is the model crate's
//! (`microrobot_model::to_urdf`, `overlay_toml`); this file only reads and writes.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use microrobot_model::Robot;
use microrobot_runtime::exit_code;

use microrobot_command_line::exit::with_code;

/// `microrobot robot ...`.
#[derive(Debug, clap::Subcommand)]
pub enum RobotCommand {
    /// Write a robot as URDF (cylinders along the links as visuals). Without `--out`
    /// the URDF goes to stdout; with it, the URDF goes to that file and the overlay that
    /// loads it as the same robot (acceleration and jerk limits, rotor inertia, gear
    /// ratios, payload, tip link `tool`) beside it as `<name>.overlay.toml`.
    Urdf(UrdfArgs),
}

/// Options of `microrobot robot urdf`.
#[derive(Debug, clap::Args)]
pub struct UrdfArgs {
    /// Robot file: DH TOML, `.urdf`, or an overlay naming a URDF.
    #[arg(value_name = "ROBOT_FILE")]
    pub robot: PathBuf,
    /// URDF file to write (its overlay is written beside it).
    #[arg(long, short = 'o', value_name = "FILE.urdf")]
    pub out: Option<PathBuf>,
}

/// Runs `microrobot robot ...`.
pub fn main(cmd: RobotCommand) -> Result<()> {
    match cmd {
        RobotCommand::Urdf(args) => urdf(&args),
    }
}

/// The overlay's path for `urdf`: `<dir>/<stem>.overlay.toml`.
pub fn overlay_path(urdf: &Path) -> PathBuf {
    let stem = urdf
        .file_stem()
        .map_or_else(|| "robot".into(), |s| s.to_string_lossy().into_owned());
    urdf.with_file_name(format!("{stem}.overlay.toml"))
}

fn urdf(args: &UrdfArgs) -> Result<()> {
    let robot = Robot::from_file(&args.robot)
        .map_err(|e| anyhow::anyhow!("robot file {}: {e}", args.robot.display()))
        .map_err(with_code(exit_code::BAD_CONFIG))?;
    let text = microrobot_model::to_urdf(&robot);
    let Some(out) = &args.out else {
        print!("{text}");
        return Ok(());
    };
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .filter(|n| !n.is_empty())
        .with_context(|| format!("--out {}: not a file name", out.display()))?;
    let overlay = overlay_path(out);
    std::fs::write(out, &text).with_context(|| format!("cannot write {}", out.display()))?;
    std::fs::write(&overlay, microrobot_model::overlay_toml(&robot, &name))
        .with_context(|| format!("cannot write {}", overlay.display()))?;
    println!(
        "wrote {} ({} joints) and {} (load the robot from the overlay: it adds what URDF cannot say)",
        out.display(),
        robot.dof(),
        overlay.display()
    );
    Ok(())
}
