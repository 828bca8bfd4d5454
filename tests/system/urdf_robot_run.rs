//! A robot from its URDF runs in the real pipeline like the seed arm: the Panda
//! (`config/robots/panda.toml`, an overlay on the URDF adding the rate limits a URDF
//! lacks) runs its demo program to the end; a URDF robot without those limits is refused
//! by `check` and `run` before anything starts, naming the overlay keys to add.

use crate::common::*;
use microrobot_runtime::exit_code;

fn panda_config(
    dir: &std::path::Path,
    instance: &str,
    robot: &std::path::Path,
) -> std::path::PathBuf {
    let text = format!(
        "instance = \"{instance}\"\nrobot = \"{}\"\nprogram = \"{}\"\nlockstep = true\n\n\
         [actuator.sim]\ninitial_q_deg = [0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0]\n\n\
         [realtime]\ncpu_affinity = []\npm_qos = false\nmlockall = false\n",
        robot.display(),
        repo().join("config/programs/panda-demo.toml").display()
    );
    let path = dir.join(format!("{instance}.toml"));
    std::fs::write(&path, text).expect("write config");
    path
}

#[test]
fn the_panda_from_its_urdf_runs_its_program_to_the_end() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("panda-run");
    let cfg = panda_config(dir.path(), &inst, &repo().join("config/robots/panda.toml"));
    let json = dir.path().join("summary.json");
    let done = run(
        &[
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--summary-json",
            json.to_str().expect("utf-8"),
        ],
        120.0,
    );
    assert_eq!(done.code(), Some(0), "{}", done.stderr);
    let s = summary(&json);
    assert_eq!(s["exit_ok"], true, "{s}");
    assert_eq!(s["program"]["state"], "finished", "{s}");
    assert_eq!(s["lost_messages"], 0, "{s}");
    let err = joints(&s, "tracking_error_max_rad");
    assert_eq!(err.len(), 7, "seven joints tracked: {s}");
    assert!(max_of(&err) < 5e-2, "tracking error {err:?}");
    let tau = joints(&s, "peak_torque_nm");
    assert!(
        tau.iter().any(|&t| t > 1.0),
        "the arm was driven against gravity: {tau:?}"
    );
}

#[test]
fn a_urdf_robot_without_rate_limits_is_refused_naming_the_overlay_keys() {
    let dir = tempfile::tempdir().expect("tempdir");
    let overlay = dir.path().join("ur5.toml");
    std::fs::write(
        &overlay,
        format!(
            "[robot]\nurdf = \"{}\"\n",
            repo().join("tests/reference/urdf/ur5_robot.urdf").display()
        ),
    )
    .expect("write overlay");
    let inst = instance("ur5-refused");
    let cfg = dir.path().join("ur5-pipe.toml");
    std::fs::write(
        &cfg,
        format!(
            "instance = \"{inst}\"\nrobot = \"{}\"\n\n[realtime]\ncpu_affinity = []\npm_qos = false\nmlockall = false\n",
            overlay.display()
        ),
    )
    .expect("write config");
    let c = cfg.to_str().expect("utf-8");
    let check = run(&["check", "--config", c], 30.0);
    let said = format!("{}{}", check.stdout, check.stderr);
    assert_eq!(
        check.code(),
        Some(i32::from(exit_code::BAD_CONFIG)),
        "{said}"
    );
    assert!(
        said.contains("joints.shoulder_pan_joint.acc_deg_s2")
            && said.contains("joints.wrist_3_joint.jerk_deg_s3"),
        "{said}"
    );
    let r = run(&["run", "--config", c, "--duration", "2"], 30.0);
    assert_eq!(
        r.code(),
        Some(i32::from(exit_code::BAD_CONFIG)),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr.contains("joints.elbow_joint.acc_deg_s2"),
        "{}",
        r.stderr
    );
}
