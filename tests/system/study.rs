//! System test of `microrobot study`: the seed arm's study written into a temp dir,
//! its files and figures, its numbers held against the model and trajectory
//! libraries, and a verdict that changes when the robot changes.

use std::path::{Path, PathBuf};

use microrobot_model::{ModelData, Robot, rnea};
use microrobot_study::{self as study, StudyArgs};
use microrobot_trajectory::{
    JointVector, KinematicLimits, MotionRequest, MotionState, Profile, Trajectory, minimum_duration,
};
use serde_json::Value;

const DEG: f64 = std::f64::consts::PI / 180.0;

/// The seed's Table 4 motion in the program format of config/programs/README.md.
const TABLE4: &str = r#"
[program]
name = "seed-table4"
dof = 6

[[segment]]
name = "to theta_i"
q_deg = [-180.0, -90.0, 0.0, -180.0, -90.0, -180.0]
profile = "soft"

[[segment]]
name = "theta_i to theta_f"
q_deg = [180.0, 90.0, 180.0, 180.0, 90.0, 180.0]
profile = "soft"
duration_s = 5.0
"#;
const THETA_I: [f64; 6] = [-180.0, -90.0, 0.0, -180.0, -90.0, -180.0];
const THETA_F: [f64; 6] = [180.0, 90.0, 180.0, 180.0, 90.0, 180.0];

fn seed_robot_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/robots/seed-arm.toml")
}

/// Small settings so the debug build stays quick.
fn quick_args(robot: &Path, program: &Path, out: &Path) -> StudyArgs {
    let mut a = StudyArgs::new(robot, program, out);
    a.workspace_samples = 20_000;
    a.steps = 600;
    a.check_samples = 200;
    a.quintic_acc_deg_s2 = Some(vec![5.0, -5.0]);
    a
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

fn case<'a>(s: &'a Value, method: &str, tf: f64) -> &'a Value {
    s["cases"]
        .as_array()
        .expect("cases")
        .iter()
        .find(|c| c["method"] == method && c["tf_s"].as_f64() == Some(tf))
        .expect("case present")
}

fn verdict<'a>(s: &'a Value, id: &str) -> &'a Value {
    s["verdicts"]
        .as_array()
        .expect("verdicts")
        .iter()
        .find(|v| v["id"] == id)
        .unwrap_or_else(|| panic!("verdict {id}"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

fn seed_limits(robot: &Robot) -> KinematicLimits {
    let mut l = KinematicLimits::uniform(1.0, 1.0, 1.0, -1e6, 1e6);
    for (i, j) in robot.joints().iter().enumerate() {
        l.velocity[i] = j.limits.velocity;
        l.acceleration[i] = j.limits.acceleration;
        l.jerk[i] = j.limits.jerk;
    }
    l
}

fn table4_request(robot: &Robot, profile: Profile) -> MotionRequest {
    let mut start = JointVector::zeros();
    let mut target = JointVector::zeros();
    for i in 0..6 {
        start[i] = THETA_I[i] * DEG;
        target[i] = THETA_F[i] * DEG;
    }
    MotionRequest {
        dof: 6,
        start: MotionState::at_rest(start),
        target: MotionState::at_rest(target),
        profile,
        limits: seed_limits(robot),
    }
}

fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(b.len() > 2000, "{} is nearly empty", path.display());
    assert_eq!(
        &b[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is not a PNG",
        path.display()
    );
    let be = |k: usize| u32::from_be_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
    (be(16), be(20))
}

#[test]
fn seed_arm_study_writes_files_whose_numbers_match_the_libraries() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("seed-table4.toml");
    std::fs::write(&program, TABLE4).expect("program");
    let out = dir.path().join("study");
    let robot_path = seed_robot_path();
    study::run(quick_args(&robot_path, &program, &out)).expect("study runs");

    for f in [
        "report.md",
        "report.html",
        "summary.json",
        "data/comparison.csv",
        "data/kinematic_peaks.csv",
        "data/min_final_time.csv",
        "data/soft_time_optimal.csv",
        "data/workspace_points.csv",
        "data/jacobian_sweeps.csv",
        "data/cases/soft_5s.csv",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let s = summary(&out);
    let report = std::fs::read_to_string(out.join("report.md")).expect("report");

    // Figures: every one listed is a non-empty PNG of the stated size.
    let figs = s["figures"].as_array().expect("figures");
    assert_eq!(figs.len(), 3 + 4 * 2 + 4 * 4 * 2);
    for fig in figs {
        let file = fig["file"].as_str().expect("file");
        let size = png_size(&out.join(file));
        assert_eq!(
            size,
            (f(&fig["width"]) as u32, f(&fig["height"]) as u32),
            "{file}"
        );
        assert!(report.contains(file), "report lists {file}");
    }

    // Table 4: time-optimal soft motion per joint and synchronised (reference values).
    let alone: Vec<f64> = s["soft_time_optimal_s"]["per_joint"]
        .as_array()
        .expect("per joint")
        .iter()
        .map(f)
        .collect();
    for (i, d) in alone.iter().enumerate() {
        let expect = if [0, 3, 5].contains(&i) {
            4.854167
        } else {
            4.821429
        };
        assert!((d - expect).abs() < 1e-6, "joint {}: {d}", i + 1);
    }
    assert!((f(&s["soft_time_optimal_s"]["synchronised"]) - 4.854167).abs() < 1e-6);
    assert!(report.contains("4.854167") && report.contains("4.821429"));

    // The cubic at tf = 5 s needs 6·360/25 = 86.4 deg/s² on joint 1 (limit 80).
    let robot = Robot::from_file(&robot_path).expect("robot");
    let cubic5 = case(&s, "cubic", 5.0);
    let a1 = f(&cubic5["peak_acceleration"][0]);
    assert!((a1 / DEG - 86.4).abs() < 1e-9, "{}", a1 / DEG);
    let lib = Trajectory::plan(&table4_request(&robot, Profile::Cubic { duration: 5.0 }))
        .expect("cubic")
        .peaks();
    for i in 0..6 {
        assert!((f(&cubic5["peak_acceleration"][i]) - lib.acceleration[i]).abs() < 1e-12);
        assert!((f(&cubic5["peak_velocity"][i]) - lib.velocity[i]).abs() < 1e-12);
    }
    assert!(
        report.contains("**86.400**"),
        "the report marks 86.4 deg/s² as over the limit"
    );
    assert!(
        cubic5["violations"]
            .as_array()
            .expect("violations")
            .iter()
            .any(|v| v["joint"] == 1 && v["quantity"] == "acceleration")
    );

    // Torques: the soft motion at 5 s recomputed with the libraries on the same grid.
    let traj = Trajectory::plan(&table4_request(
        &robot,
        Profile::Soft {
            min_duration: Some(5.0),
        },
    ))
    .expect("soft");
    assert!((traj.duration() - 5.0).abs() < 1e-9);
    let mut data = ModelData::new(&robot);
    let mut peak = [0.0f64; 6];
    for k in 0..=600 {
        let smp = traj.sample(traj.duration() * k as f64 / 600.0);
        let tau = rnea(&robot, &mut data, &smp.q, &smp.qd, &smp.qdd);
        for i in 0..6 {
            peak[i] = peak[i].max(tau[i].abs());
        }
    }
    let soft5 = case(&s, "soft", 5.0);
    for (i, p) in peak.iter().enumerate() {
        let got = f(&soft5["peak_torque_nm"][i]);
        assert!(
            (got - p).abs() <= 1e-9 * p.max(1.0),
            "joint {}: {got} vs {p}",
            i + 1
        );
    }

    // Minimum final time: never below the library's kinematic minimum; for the cubic
    // (torques far below 50 N·m) equal to it: sqrt(6·360/80) = 5.196 s.
    let cubic_min = minimum_duration(&table4_request(&robot, Profile::Cubic { duration: 1.0 }))
        .expect("cubic minimum");
    assert!((cubic_min - (6.0 * 360.0 / 80.0f64).sqrt()).abs() < 1e-6);
    for m in s["min_final_time"].as_array().expect("min times") {
        let (kin, min) = (f(&m["kinematic_minimum_s"]), f(&m["minimum_s"]));
        assert!(min >= kin * (1.0 - 1e-9), "{m}");
        if m["method"] == "cubic" {
            assert!((min - cubic_min).abs() < 2e-6 * cubic_min, "{m}");
        }
        if m["method"] == "soft" {
            assert!((min - 4.854167).abs() < 1e-6, "{m}");
        }
    }

    // Verdicts are computed: with the seed's own parameters joint 3 carries the
    // highest torque (joints 1 and 2 are vertical), not joint 1 as the seed says.
    let v = verdict(&s, "highest_torque_joint");
    assert_eq!(v["value"], "3", "{v}");
    assert_eq!(v["holds"], false);
    assert_eq!(verdict(&s, "cubic_exceeds_acceleration")["holds"], true);
    assert_eq!(verdict(&s, "z_unaffected_by_joints_1_2")["holds"], true);
    assert!(report.contains("The seed's conclusions checked"));
}

#[test]
fn highest_torque_verdict_follows_gravity_onto_joint_1() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("seed-table4.toml");
    std::fs::write(&program, TABLE4).expect("program");
    let text = std::fs::read_to_string(seed_robot_path()).expect("seed robot");
    let turned = text.replace(
        "gravity_mps2 = [0.0, 0.0, -9.81]",
        "gravity_mps2 = [-9.81, 0.0, 0.0]",
    );
    assert_ne!(text, turned, "seed robot file changed shape");
    let robot = dir.path().join("seed-arm-gravity-x.toml");
    std::fs::write(&robot, turned).expect("robot");
    let out = dir.path().join("study");
    let mut args = quick_args(&robot, &program, &out);
    args.no_figures = true;
    args.workspace_samples = 2000;
    study::run(args).expect("study runs");
    let s = summary(&out);
    // Joints 1 and 2 are collinear, so both now carry the arm's whole gravity load
    // (a tie the verdict reports); joint 3 no longer does.
    let v = verdict(&s, "highest_torque_joint");
    let joints: Vec<&str> = v["value"].as_str().expect("value").split(',').collect();
    assert!(joints.contains(&"1") && !joints.contains(&"3"), "{v}");
    assert_eq!(v["holds"], true);
}

#[test]
fn a_bad_robot_or_program_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("seed-table4.toml");
    std::fs::write(&program, TABLE4).expect("program");
    let out = dir.path().join("study");

    let missing = dir.path().join("no-such-robot.toml");
    let e = study::run(quick_args(&missing, &program, &out))
        .err()
        .expect("error");
    assert!(format!("{e:#}").contains("no-such-robot.toml"), "{e:#}");

    let bad = dir.path().join("bad-robot.toml");
    std::fs::write(&bad, "[robot]\nname = 1\n").expect("bad robot");
    let e = study::run(quick_args(&bad, &program, &out))
        .err()
        .expect("error");
    assert!(format!("{e:#}").contains("bad-robot.toml"), "{e:#}");

    let bad_program = dir.path().join("bad-program.toml");
    std::fs::write(&bad_program, "[[segment]]\nq_deg = [1.0, 2.0]\n").expect("bad program");
    let e = study::run(quick_args(&seed_robot_path(), &bad_program, &out))
        .err()
        .expect("error");
    assert!(format!("{e:#}").contains("bad-program.toml"), "{e:#}");
}

/// The spherical arm (revolute, revolute, prismatic) with a program in each joint's unit.
const RRP: &str = r#"
[program]
name = "rrp"
dof = 3

[[segment]]
q_deg_mm = [-60.0, 30.0, 120.0]

[[segment]]
q_deg_mm = [60.0, 120.0, 280.0]
duration_s = 4.0
"#;

fn rrp_robot_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/robots/spherical-rrp.toml")
}

#[test]
fn a_prismatic_joint_is_reported_in_mm_and_n_and_seed_claims_are_not_checked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("rrp.toml");
    std::fs::write(&program, RRP).expect("program");
    let out = dir.path().join("study");
    let mut args = quick_args(&rrp_robot_path(), &program, &out);
    args.quintic_acc_deg_s2 = None;
    args.no_figures = true;
    args.workspace_samples = 2000;
    let st = study::run(args).expect("study runs");
    let s = summary(&out);

    // The program's mm were converted once: the boom goes from 0.12 m to 0.28 m.
    assert!((st.motion.start[2] - 0.12).abs() < 1e-12);
    assert!((st.motion.target[2] - 0.28).abs() < 1e-12);

    // CSV headers carry the joint type's SI unit.
    let csv = std::fs::read_to_string(out.join("data/cases/soft_5s.csv")).expect("case csv");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    for col in [
        "q1_rad",
        "q3_m",
        "qd3_m_s",
        "qdd3_m_s2",
        "tau_nm_1",
        "tau_n_3",
    ] {
        assert!(header.contains(&col), "{col} in {header:?}");
    }
    assert!(
        !header
            .iter()
            .any(|h| h.starts_with("q3_rad") || *h == "tau_nm_3")
    );
    let comparison = std::fs::read_to_string(out.join("data/comparison.csv")).expect("csv");
    assert!(
        comparison.starts_with("method,tf_s,duration_s,peak_tau_nm_1,peak_tau_nm_2,peak_tau_n_3,")
    );

    // The Jacobian column of the boom is unscaled m/m: a unit vector along the boom.
    let jac = std::fs::read_to_string(out.join("data/jacobian_sweeps.csv")).expect("csv");
    let mut lines = jac.lines();
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).expect(name);
    let (dx, dy, dz) = (col("dpx_m_per_m"), col("dpy_m_per_m"), col("dpz_m_per_m"));
    let mut boom_rows = 0;
    for l in lines {
        let c: Vec<&str> = l.split(',').collect();
        if c[0] != "3" {
            continue;
        }
        let v = |i: usize| c[i].parse::<f64>().expect("number");
        let norm = (v(dx).powi(2) + v(dy).powi(2) + v(dz).powi(2)).sqrt();
        assert!((norm - 1.0).abs() < 1e-9, "boom column norm {norm}: {l}");
        boom_rows += 1;
    }
    assert!(boom_rows > 0);

    // Tables: the boom in mm and N, its Jacobian in m/m, never mm/mm.
    let report = std::fs::read_to_string(out.join("report.md")).expect("report");
    assert!(
        report.contains("| 3 | mm | 120.000 | 280.000 |"),
        "Table 4 row of the boom"
    );
    assert!(report.contains("200.000 N |"), "force limit in N");
    assert!(report.contains("peak |τ| j3 (N)") && report.contains("peak |τ| j1 (N·m)"));
    assert!(report.contains("j3 (mm/s)"));
    assert!(report.contains("m/m") && !report.contains("mm/mm"));

    // JSON: per-joint keys in the joint's unit; no all-revolute arrays.
    let soft = case(&s, "soft", 5.0);
    let boom = &soft["joints"][2];
    assert_eq!(boom["kind"], "prismatic");
    assert!(
        boom["peak_velocity_m_s"].is_number() && boom["peak_tau_n"].is_number(),
        "{boom}"
    );
    assert!(boom.get("peak_velocity_rad_s").is_none() && boom.get("peak_tau_nm").is_none());
    assert!(soft.get("peak_torque_nm").is_none());

    // Not the seed arm: nothing confirmed or refuted, every claim not applicable.
    assert_eq!(s["seed_arm"], false);
    for v in s["verdicts"].as_array().expect("verdicts") {
        assert_eq!(v["status"], "not_applicable", "{v}");
        assert!(v["holds"].is_null(), "{v}");
    }
    let verdicts = report
        .split("## 7.")
        .nth(1)
        .and_then(|t| t.split("## 8.").next())
        .expect("verdict section")
        .to_lowercase();
    for word in ["confirmed", "pass", "holds", "refuted"] {
        assert!(!verdicts.contains(word), "{word} in {verdicts}");
    }
    assert!(report.contains("not the seed arm"));
}

#[test]
fn the_seed_arm_is_recognised_by_its_parameters_not_its_file_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("seed-table4.toml");
    std::fs::write(&program, TABLE4).expect("program");
    let text = std::fs::read_to_string(seed_robot_path()).expect("seed robot");
    let run = |robot_text: &str, file: &str| {
        let robot = dir.path().join(file);
        std::fs::write(&robot, robot_text).expect("robot");
        let out = dir.path().join(format!("study-{file}"));
        let mut args = quick_args(&robot, &program, &out);
        args.no_figures = true;
        args.workspace_samples = 2000;
        study::run(args).expect("study runs");
        summary(&out)
    };
    // Renamed, same parameters: still the seed arm, claims checked.
    let s = run(&text, "my-arm.toml");
    assert_eq!(s["seed_arm"], true);
    assert!(
        s["verdicts"]
            .as_array()
            .expect("verdicts")
            .iter()
            .all(|v| v["holds"].is_boolean())
    );
    // Same name, a longer link: another arm, claims not checked.
    let longer = text.replacen("a_mm = 50.0", "a_mm = 60.0", 1);
    assert_ne!(longer, text, "seed robot file changed shape");
    let s = run(&longer, "seed-arm.toml");
    assert_eq!(s["seed_arm"], false);
    assert!(
        s["verdicts"]
            .as_array()
            .expect("verdicts")
            .iter()
            .all(|v| v["status"] == "not_applicable")
    );
}

#[test]
fn a_unit_that_does_not_fit_the_joint_type_names_file_key_and_joint() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("rrp-in-degrees.toml");
    std::fs::write(&program, RRP.replace("q_deg_mm", "q_deg")).expect("program");
    let out = dir.path().join("study");
    let e = study::run(quick_args(&rrp_robot_path(), &program, &out))
        .err()
        .expect("a length given in degrees");
    let e = format!("{e:#}");
    for needle in [
        "rrp-in-degrees.toml",
        "q_deg",
        "joint 3 (`boom`)",
        "prismatic",
    ] {
        assert!(e.contains(needle), "{needle} in {e}");
    }
}
