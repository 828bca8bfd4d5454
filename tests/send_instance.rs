//! `send` talks to the running instance: it checks targets against the robot that
//! instance runs (not the config of the current directory), and takes `--instance` and
//! `--config` before or after the command.

mod common;

use common::*;

/// The seed arm's first two joints as a robot of its own.
fn two_joint_robot(dir: &std::path::Path) -> std::path::PathBuf {
    let seed = std::fs::read_to_string(seed_arm()).expect("seed arm");
    let mut out = String::new();
    let mut joints = 0;
    for block in seed.split("\n[[joints]]\n") {
        if out.is_empty() {
            out.push_str(&block.replace("name = \"seed-arm\"", "name = \"two-joint\""));
            continue;
        }
        joints += 1;
        if joints <= 2 {
            out.push_str("\n[[joints]]\n");
            // The block may end with a trailing table ([tool], [payload]): keep the joint only.
            let joint = block.split("\n[").next().unwrap_or(block);
            out.push_str(joint);
            out.push('\n');
        }
    }
    let path = dir.join("two-joint.toml");
    std::fs::write(&path, out).expect("write robot");
    path
}

#[test]
fn send_checks_targets_against_the_robot_the_instance_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("send-2dof");
    let robot = two_joint_robot(dir.path());
    let cfg_path = dir.path().join("pipeline.toml");
    std::fs::write(
        &cfg_path,
        format!(
            "instance = \"{inst}\"\nrobot = \"{}\"\n\n[realtime]\ncpu_affinity = []\npm_qos = false\nmlockall = false\n",
            robot.display()
        ),
    )
    .expect("write config");
    let proc = start_holding(&inst, &cfg_path, 60, None);

    // No --config: the shipped config names the 6-joint seed arm, but the instance runs
    // the 2-joint robot, and its joints are what a target is checked against.
    let ok = run(
        &[
            "send",
            "move",
            "--deg",
            "--joints",
            "10,5",
            "--instance",
            &inst,
        ],
        60.0,
    );
    assert_eq!(ok.code(), Some(0), "{}{}", ok.stdout, ok.stderr);
    let six = run(
        &[
            "send",
            "--instance",
            &inst,
            "move",
            "--joints",
            "0,0,0,0,0,0",
        ],
        60.0,
    );
    assert_ne!(six.code(), Some(0));
    assert!(
        six.stderr
            .contains("6 values, but robot `two-joint` has 2 joints"),
        "{}",
        six.stderr
    );
    let far = run(
        &[
            "send",
            "move",
            "--deg",
            "--joints",
            "10,95",
            "--instance",
            &inst,
        ],
        60.0,
    );
    assert_ne!(far.code(), Some(0));
    assert!(
        far.stderr
            .contains("j2 target 95° is outside its range [-90°, 90°]"),
        "{}",
        far.stderr
    );
    // A refusal by the planner names the joint, the quantity, the value and the limit,
    // in the units typed (j1's velocity limit is 135°/s), with the refusal's exit code.
    let fast = run(
        &[
            "send",
            "--instance",
            &inst,
            "move",
            "--deg",
            "--joints",
            "90,0",
            "--profile",
            "quintic",
            "--duration",
            "0.5",
        ],
        60.0,
    );
    assert_eq!(
        fast.code(),
        Some(microrobot_runtime::exit_code::JOB_FAILED as i32),
        "{}",
        fast.stderr
    );
    // The peak depends on where the earlier move left the arm; the limit does not.
    assert!(
        fast.stderr.contains("refused the command (seq ")
            && fast
                .stderr
                .contains("): no trajectory within the limits: j1 velocity ")
            && fast.stderr.contains("°/s is outside [-135°/s, 135°/s]"),
        "{}",
        fast.stderr
    );
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
}
