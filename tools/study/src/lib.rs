//! The offline commands of `microrobot`, which read a robot file and run no pipeline:
//! `microrobot study` (below), `eval model` ([`eval_model`]), `eval trajectory`
//! ([`eval_trajectory`]) and `robot urdf` ([`robot_cmd`]).
//!
//! `microrobot study`: the seed chapter's study regenerated from a robot file and a
//! motion program — Tables 2–5 as read, the workspace, the Jacobian and tool paths,
//! the four trajectory methods at several final times with their torque histories
//! by inverse dynamics, a comparison table, the minimum final time per method found
//! by search, and the seed's conclusions checked against the numbers.
//!
//! Output (in `--out`): `report.md` and `report.html`, PNG figures under `figures/`,
//! CSV data under `data/`, and `summary.json` (the tables' numbers and verdicts, SI).

mod cases;
pub mod eval_model;
pub mod eval_trajectory;
mod figures;
mod kinematics;
mod mintime;
mod motion;
pub mod plot;
mod report;
pub mod robot_cmd;
pub mod units;
mod verdicts;

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use microrobot_model::Robot;
use microrobot_trajectory::{MotionRequest, Profile, Trajectory};

pub use cases::Method;

/// Arguments of `microrobot study`.
#[derive(Debug, Clone, clap::Args)]
pub struct StudyArgs {
    /// Robot description (TOML), e.g. config/robots/seed-arm.toml.
    #[arg(long)]
    pub robot: PathBuf,
    /// Motion program (TOML) whose first motion is studied, e.g. config/programs/seed-table4.toml.
    #[arg(long)]
    pub program: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Final times to compare (s), comma separated.
    #[arg(long, value_delimiter = ',', default_values_t = vec![5.0, 10.0, 20.0, 60.0])]
    pub final_times: Vec<f64>,
    /// Joint-space samples for the workspace.
    #[arg(long, default_value_t = 1_000_000)]
    pub workspace_samples: usize,
    /// Time steps per trajectory (uniform on [0, tf]) for histories and statistics.
    #[arg(long, default_value_t = 6000)]
    pub steps: usize,
    /// Torque samples per check in the minimum-final-time search.
    #[arg(long, default_value_t = 2000)]
    pub check_samples: usize,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Quintic boundary accelerations θ̈i,θ̈f of every revolute joint, deg/s²; the
    /// seed's Table 4 uses 5,-5. Default: the program's, else 0.
    #[arg(long, value_delimiter = ',', num_args = 1.., allow_hyphen_values = true)]
    pub quintic_acc_deg_s2: Option<Vec<f64>>,
    /// Quintic boundary accelerations of every prismatic joint, mm/s² (two values,
    /// start,end). Default: the program's, else 0.
    #[arg(long, value_delimiter = ',', num_args = 1.., allow_hyphen_values = true)]
    pub quintic_acc_mm_s2: Option<Vec<f64>>,
    /// Skip the PNG figures (numbers, CSV and report only).
    #[arg(long)]
    pub no_figures: bool,
}

impl StudyArgs {
    /// The defaults of the command line for `robot`, `program` and `out`.
    pub fn new(
        robot: impl Into<PathBuf>,
        program: impl Into<PathBuf>,
        out: impl Into<PathBuf>,
    ) -> Self {
        StudyArgs {
            robot: robot.into(),
            program: program.into(),
            out: out.into(),
            final_times: vec![5.0, 10.0, 20.0, 60.0],
            workspace_samples: 1_000_000,
            steps: 6000,
            check_samples: 2000,
            threads: 0,
            quintic_acc_deg_s2: None,
            quintic_acc_mm_s2: None,
            no_figures: false,
        }
    }
}

/// Everything the study computed (SI).
pub struct Study {
    /// The robot as read.
    pub robot: Robot,
    /// The studied motion.
    pub motion: motion::StudyMotion,
    /// Settings used.
    pub args: StudyArgs,
    /// Workspace estimate.
    pub workspace: kinematics::WorkspaceStudy,
    /// Joint sweeps (Jacobian columns and tool paths).
    pub sweeps: Vec<kinematics::Sweep>,
    /// Rank of the Jacobian at the reference configuration.
    pub rank: usize,
    /// Largest rank over random configurations.
    pub max_rank: usize,
    /// Time-optimal soft-motion duration of each joint alone (s).
    pub soft_alone: Vec<f64>,
    /// Synchronised time-optimal soft-motion duration (s).
    pub soft_sync: f64,
    /// Each method at each final time, method-major.
    pub cases: Vec<cases::Case>,
    /// Minimum final time per method.
    pub mintimes: Vec<mintime::MinTime>,
    /// `None` when the robot is the seed arm, else how it differs
    /// ([`units::seed_arm_difference`]).
    pub not_seed: Option<String>,
    /// The seed's conclusions: checked on the seed arm, measured elsewhere.
    pub verdicts: Vec<verdicts::Verdict>,
    /// Figures written: (file relative to `out`, width, height, caption).
    pub figures: Vec<(String, u32, u32, String)>,
    /// Wall time per step (name, s).
    pub timings: Vec<(String, f64)>,
}

/// Runs the study and writes the report; see the module documentation.
pub fn main(args: StudyArgs) -> Result<()> {
    let t0 = Instant::now();
    let study = run(args)?;
    eprintln!(
        "study written to {} in {:.2} s",
        study.args.out.join("report.md").display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn bar(len: u64, msg: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{msg:28} [{bar:32}] {pos}/{len} {elapsed}") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(msg.to_string());
    pb
}

/// Runs `f` on each item on `threads` scoped workers, results in item order.
fn parallel<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    pb: &ProgressBar,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<(usize, R)>> = Mutex::new(Vec::with_capacity(items.len()));
    std::thread::scope(|s| {
        for _ in 0..threads.max(1).min(items.len().max(1)) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(item) = items.get(i) else { break };
                    let r = f(item);
                    if let Ok(mut o) = out.lock() {
                        o.push((i, r));
                    }
                    pb.inc(1);
                }
            });
        }
    });
    let mut v = out.into_inner().unwrap_or_else(|p| p.into_inner());
    v.sort_by_key(|(i, _)| *i);
    v.into_iter().map(|(_, r)| r).collect()
}

/// Runs the study and writes every output file; returns what was computed.
pub fn run(args: StudyArgs) -> Result<Study> {
    let robot = Robot::from_file(&args.robot)
        .with_context(|| format!("robot file {}", args.robot.display()))?;
    let joints: Vec<_> = robot
        .joints()
        .iter()
        .map(|j| (j.kind, j.name.as_str()))
        .collect();
    let mut motion = motion::read(&args.program, &joints)?;
    let robot = match &motion.limits {
        Some(l) => with_limits(&robot, l)?,
        None => robot,
    };
    for (flag, given, kind) in [
        (
            "--quintic-acc-deg-s2",
            &args.quintic_acc_deg_s2,
            microrobot_model::JointKind::Revolute,
        ),
        (
            "--quintic-acc-mm-s2",
            &args.quintic_acc_mm_s2,
            microrobot_model::JointKind::Prismatic,
        ),
    ] {
        let Some(a) = given else { continue };
        let [a0, a1] = a[..] else {
            bail!("{flag}: give two values, θ̈i,θ̈f (got {})", a.len());
        };
        if !robot.joints().iter().any(|j| j.kind == kind) {
            bail!("{flag}: the robot has no {} joint", units::kind_name(kind));
        }
        for (i, j) in robot.joints().iter().enumerate() {
            if j.kind == kind {
                let sc = units::Units(kind).scale();
                motion.start_acc[i] = a0 / sc;
                motion.target_acc[i] = a1 / sc;
            }
        }
    }
    if args.final_times.is_empty() {
        bail!("--final-times: give at least one final time");
    }
    for &tf in &args.final_times {
        if !(tf > 0.0 && tf.is_finite()) {
            bail!("--final-times: {tf} is not a positive finite number of seconds");
        }
    }
    for (i, j) in robot.joints().iter().enumerate() {
        let u = units::Units(j.kind);
        for (what, q) in [("start", motion.start[i]), ("target", motion.target[i])] {
            if !j.limits.contains(q) {
                bail!(
                    "{}: joint {} (`{}`) {what} {:.4} is outside the robot's range [{:.4}, {:.4}] ({})",
                    args.program.display(),
                    i + 1,
                    j.name,
                    q * u.scale(),
                    j.limits.min * u.scale(),
                    j.limits.max * u.scale(),
                    u.display(0)
                );
            }
        }
    }
    let threads = if args.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        args.threads
    };
    let out = &args.out;
    for dir in [out.clone(), out.join("figures"), out.join("data")] {
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    }
    let mut timings = Vec::new();

    // Workspace, Jacobian sweeps.
    let t = Instant::now();
    let pb = bar(args.workspace_samples as u64, "workspace");
    let workspace = kinematics::workspace(&robot, args.workspace_samples, &|done, total| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    })?;
    pb.finish_and_clear();
    let sweeps = kinematics::sweeps(&robot);
    let rank = kinematics::reference_rank(&robot);
    let max_rank = kinematics::max_rank(&robot, 2000);
    timings.push((
        "workspace and Jacobian".to_string(),
        t.elapsed().as_secs_f64(),
    ));

    // Time-optimal soft motion per joint alone and synchronised (Table 4 check).
    let mut soft_alone = Vec::new();
    let limits = cases::planning_limits(&robot);
    for i in 0..robot.dof() {
        let mut req = cases::request(&robot, &motion, Method::Soft, 1.0);
        req.profile = Profile::Soft { min_duration: None };
        req.dof = 1;
        req.start.q[0] = motion.start[i];
        req.target.q[0] = motion.target[i];
        req.limits.velocity[0] = limits.velocity[i];
        req.limits.acceleration[0] = limits.acceleration[i];
        req.limits.jerk[0] = limits.jerk[i];
        soft_alone.push(duration_of(&req)?);
    }
    let mut req = cases::request(&robot, &motion, Method::Soft, 1.0);
    req.profile = Profile::Soft { min_duration: None };
    let soft_sync = duration_of(&req)?;

    // Cases.
    let t = Instant::now();
    let jobs: Vec<(Method, f64)> = Method::ALL
        .iter()
        .flat_map(|&m| args.final_times.iter().map(move |&tf| (m, tf)))
        .collect();
    let pb = bar(jobs.len() as u64, "trajectories and torques");
    let results = parallel(&jobs, threads, &pb, |&(m, tf)| {
        cases::run_case(&robot, &motion, m, tf, args.steps)
    });
    pb.finish_and_clear();
    let cases = results.into_iter().collect::<Result<Vec<_>>>()?;
    timings.push((
        "trajectories and torques".to_string(),
        t.elapsed().as_secs_f64(),
    ));

    // Minimum final times.
    let t = Instant::now();
    let pb = bar(4, "minimum final time search");
    let mintimes = parallel(&Method::ALL, threads, &pb, |&m| {
        mintime::search(&robot, &motion, m, args.check_samples)
    });
    pb.finish_and_clear();
    let mintimes = mintimes.into_iter().collect::<Result<Vec<_>>>()?;
    timings.push((
        "minimum final time search".to_string(),
        t.elapsed().as_secs_f64(),
    ));

    let not_seed = units::seed_arm_difference(&robot);
    let verdicts = verdicts::compute(
        &robot,
        not_seed.as_deref(),
        &motion,
        &cases,
        &mintimes,
        &sweeps,
        &args.final_times,
        args.check_samples,
    );

    let mut study = Study {
        robot,
        motion,
        args: args.clone(),
        workspace,
        sweeps,
        rank,
        max_rank,
        soft_alone,
        soft_sync,
        cases,
        mintimes,
        not_seed,
        verdicts,
        figures: Vec::new(),
        timings,
    };

    // Figures and data.
    let t = Instant::now();
    let jobs = if args.no_figures {
        Vec::new()
    } else {
        figures::jobs(&study)
    };
    let pb = bar(jobs.len() as u64, "figures");
    let drawn = parallel(&jobs, threads, &pb, |job| {
        figures::draw_job(&study, job, out)
    });
    pb.finish_and_clear();
    study.figures = drawn.into_iter().collect::<Result<Vec<_>>>()?;
    report::write_data(&study, out)?;
    study
        .timings
        .push(("figures and data".to_string(), t.elapsed().as_secs_f64()));
    report::write_report(&study, out)?;
    Ok(study)
}

/// `robot` with the program's velocity, acceleration and jerk limits.
fn with_limits(robot: &Robot, l: &[microrobot_model::JointVector; 3]) -> Result<Robot> {
    let joints = robot
        .joints()
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let mut j = j.clone();
            j.limits.velocity = l[0][i];
            j.limits.acceleration = l[1][i];
            j.limits.jerk = l[2][i];
            j
        })
        .collect();
    Robot::new(
        robot.name(),
        robot.gravity(),
        joints,
        *robot.tool(),
        robot.payload().copied(),
    )
    .map_err(|e| anyhow::anyhow!("robot with the program's limits: {e}"))
}

fn duration_of(req: &MotionRequest) -> Result<f64> {
    Ok(Trajectory::plan(req)
        .context("time-optimal soft motion")?
        .duration())
}
