//! The planner reports how its program ended: finished, abandoned (and why) or never run
//! (and why), so a supervisor never takes an abandoned program for a finished one.

use std::path::{Path, PathBuf};

use microrobot_messages::{
    CommandKind, Header, JointState, LifecycleState, MotionCommand, ProgramEnd, ProgramState,
    state_flags,
};
use microrobot_model::Robot;
use microrobot_planner::PlannerCore;
use microrobot_planner::program::ProgramRunner;
use microrobot_runtime::config::PipelineConfig;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn cfg() -> PipelineConfig {
    PipelineConfig {
        robot: repo().join("config/robots/seed-arm.toml"),
        ..Default::default()
    }
}

/// A one-segment program to `q_deg`, written to a file of its own.
fn program_file(tag: &str, q_deg: [f64; 6]) -> PathBuf {
    let path = std::env::temp_dir().join(format!(
        "microrobot-outcome-{tag}-{}.toml",
        std::process::id()
    ));
    let q: Vec<String> = q_deg.iter().map(|v| format!("{v:.1}")).collect();
    let text = format!(
        "[program]\nname = \"{tag}\"\ndof = 6\n[[segment]]\nq_deg = [{}]\nprofile = \"soft\"\n",
        q.join(", ")
    );
    std::fs::write(&path, text).expect("write program");
    path
}

fn planner(program: &Path) -> PlannerCore {
    let cfg = cfg();
    let robot = Robot::from_file(&cfg.robot).expect("seed arm");
    let runner = ProgramRunner::from_file(program, &robot).expect("program loads");
    PlannerCore::new(&robot, &cfg, Some(runner))
}

/// A measured state at rest at `q` (j3 at 10°, inside its [0°, 180°] range).
fn state(seq: u64, stamp_ns: u64, qd0: f64, flags: u32) -> JointState {
    let mut s = JointState {
        dof: 6,
        header: Header {
            seq,
            stamp_ns,
            ..Default::default()
        },
        flags,
        lifecycle: LifecycleState::Active as u32,
        ..Default::default()
    };
    s.q[2] = 10f64.to_radians();
    s.qd[0] = qd0;
    s
}

const TARGET: [f64; 6] = [10.0, 5.0, 20.0, 0.0, 5.0, 0.0];

#[test]
fn a_program_run_to_its_end_is_finished() {
    let mut p = planner(&program_file("finish", TARGET));
    assert_eq!(
        p.program_outcome(),
        (ProgramState::Pending, ProgramEnd::None)
    );
    assert!(p.accept_state(&state(1, 0, 0.0, 0), 1, 0));
    assert_eq!(
        p.program_outcome(),
        (ProgramState::Running, ProgramEnd::None)
    );
    for _ in 0..20_000 {
        p.tick(0);
        if p.program_done() {
            break;
        }
    }
    assert!(p.program_done());
    assert_eq!(
        p.program_outcome(),
        (ProgramState::Finished, ProgramEnd::None)
    );
}

#[test]
fn a_stop_command_abandons_the_program_and_says_so() {
    let mut p = planner(&program_file("stop", TARGET));
    assert!(p.accept_state(&state(1, 0, 0.0, 0), 1, 0));
    for _ in 0..200 {
        p.tick(0);
    }
    let stop = MotionCommand {
        kind: CommandKind::Stop as u32,
        ..Default::default()
    };
    p.on_command(&stop, 0).expect("stop accepted");
    for _ in 0..20_000 {
        p.tick(0);
        if p.program_done() {
            break;
        }
    }
    // Done (at rest) like a finished program, but reported as abandoned.
    assert!(p.program_done());
    assert_eq!(
        p.program_outcome(),
        (ProgramState::Abandoned, ProgramEnd::Command)
    );
}

#[test]
fn a_stale_measured_state_abandons_the_program() {
    let mut p = planner(&program_file("stale", TARGET));
    assert!(p.accept_state(&state(1, 0, 0.0, 0), 1, 0));
    p.tick(0);
    // Far beyond `stale_ms` after the only state.
    p.check_state(10_000_000_000);
    assert_eq!(
        p.program_outcome(),
        (ProgramState::Abandoned, ProgramEnd::StaleState)
    );
}

#[test]
fn a_program_is_not_run_from_a_moving_arm_or_a_latched_actuator() {
    let mut p = planner(&program_file("moving", TARGET));
    assert!(p.accept_state(&state(1, 0, 0.2, 0), 1, 0));
    assert_eq!(
        p.program_outcome(),
        (ProgramState::NotRun, ProgramEnd::MovingAtStart)
    );

    let mut p = planner(&program_file("latched", TARGET));
    assert!(p.accept_state(&state(1, 0, 0.0, state_flags::SAFE_STATE), 1, 0));
    assert_eq!(
        p.program_outcome(),
        (ProgramState::NotRun, ProgramEnd::SafeState)
    );
}

#[test]
fn a_program_that_cannot_be_planned_is_not_run() {
    // j5's range is [-90°, 90°].
    let mut p = planner(&program_file("range", [0.0, 0.0, 20.0, 0.0, 120.0, 0.0]));
    assert!(p.accept_state(&state(1, 0, 0.0, 0), 1, 0));
    assert_eq!(
        p.program_outcome(),
        (ProgramState::NotRun, ProgramEnd::CannotPlan)
    );
    // Nothing moves: the setpoint holds the measured position.
    let sp = p.tick(0);
    assert!(sp.qd.iter().all(|v| *v == 0.0));
    assert_eq!(sp.q[2], 10f64.to_radians());
}
