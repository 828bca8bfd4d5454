//! `send` talks to the running instance: it checks targets against the robot that
//! instance runs (not the config of the current directory), and takes `--instance` and
//! `--config` before or after the command.

use crate::common::*;

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

/// `send --wait` returns once the arm holds again, with the motion's duration, and fails
/// (exit 7) naming how when the motion ends any other way.
#[test]
fn send_wait_reports_the_motion_done_or_how_it_ended() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("send-wait");
    let cfg = write_config(dir.path(), &inst, "", "");
    let proc = start_holding(&inst, &cfg, 90, None);
    let send = |args: &[&str]| {
        let mut all = vec!["send", "--instance", inst.as_str()];
        all.extend_from_slice(args);
        run(&all, 60.0)
    };

    let done = send(&["move", "--wait", "--deg", "--joints", "10,10,10,10,10,10"]);
    assert_eq!(done.code(), Some(0), "{}{}", done.stdout, done.stderr);
    let secs: f64 = done
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("done: holding after "))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no duration in {:?}", done.stdout));
    // A 10° time-optimal move of the seed arm's slowest joint takes about a second; the
    // duration is the planner's logical time, so it cannot be zero or minutes.
    assert!(secs > 0.2 && secs < 10.0, "{secs} s");
    // At rest already: a stop is done at once.
    let stop = send(&["stop", "--wait"]);
    assert_eq!(stop.code(), Some(0), "{}{}", stop.stdout, stop.stderr);
    assert!(
        stop.stdout.contains("done: holding after"),
        "{}",
        stop.stdout
    );

    // An e-stop while a slow move is under way ends the waited-for motion.
    let inst2 = inst.clone();
    let estop = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(700));
        run(&["send", "--instance", &inst2, "estop"], 60.0)
    });
    let cut = send(&[
        "move",
        "--wait",
        "--deg",
        "--joints",
        "-40,-40,80,-40,-40,-40",
        "--limit-scale",
        "0.3",
    ]);
    let estop = estop.join().expect("estop thread");
    assert_eq!(estop.code(), Some(0), "{}", estop.stderr);
    assert_eq!(
        cut.code(),
        Some(microrobot_runtime::exit_code::JOB_FAILED as i32),
        "{}{}",
        cut.stdout,
        cut.stderr
    );
    assert!(
        cut.stderr.contains("the motion did not finish:"),
        "{}",
        cut.stderr
    );
    assert!(
        cut.stderr.contains("an e-stop is braking the arm"),
        "{}",
        cut.stderr
    );
    // --wait is refused where nothing ends in a hold.
    let bad = send(&["estop", "--wait"]);
    assert_ne!(bad.code(), Some(0));
    assert!(
        bad.stderr.contains("--wait applies to `move` and `stop`"),
        "{}",
        bad.stderr
    );

    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_ne!(out.code(), None, "the run died of a signal: {}", out.stderr);
}
