//! Every class of bad robot file is refused with an error naming the file and
//! the key (docs/seed-arm.md, "Robot description").
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use microrobot_model::{Robot, RobotFileError};

const GOOD: &str = r#"
[robot]
name = "two-joint"
gravity_mps2 = [0.0, 0.0, -9.81]

[[joints]]
name = "j1"
kind = "revolute"
dh = { theta_deg = 0.0, d_mm = 100.0, a_mm = 0.0, alpha_deg = 90.0 }
limits = { min_deg = -170.0, max_deg = 170.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 50.0 }
link = { mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0]] }

[[joints]]
name = "j2"
kind = "prismatic"
dh = { theta_deg = 0.0, d_mm = 0.0, a_mm = 0.0, alpha_deg = 0.0 }
limits = { min_mm = 0.0, max_mm = 200.0, vel_mm_s = 100.0, acc_mm_s2 = 100.0, jerk_mm_s3 = 1000.0, force_n = 100.0 }
link = { mass_kg = 0.5, com_mm = [0.0, 0.0, -50.0], inertia_kgmm2 = [[50.0, 0.0, 0.0], [0.0, 50.0, 0.0], [0.0, 0.0, 10.0]] }
"#;

fn load(text: &str) -> Result<Robot, RobotFileError> {
    Robot::from_toml_str(text, "bad-arm.toml")
}

/// Loads `text`, expects an error about `key` and returns its message.
#[track_caller]
fn refused(text: &str, key: &str) -> String {
    match load(text) {
        Ok(_) => panic!("accepted a bad file (expected an error about {key})"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("bad-arm.toml: "),
                "message does not name the file: {msg}"
            );
            assert_eq!(e.key(), Some(key), "wrong key in: {msg}");
            assert!(msg.contains(key), "message does not name the key: {msg}");
            msg
        }
    }
}

#[test]
fn the_good_file_loads() {
    let robot = load(GOOD).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(robot.dof(), 2);
    assert_eq!(
        robot.joints()[1].kind,
        microrobot_model::JointKind::Prismatic
    );
    assert!((robot.joints()[1].limits.max - 0.2).abs() < 1e-15);
    assert!((robot.joints()[0].limits.min + 170f64.to_radians()).abs() < 1e-15);
}

#[test]
fn unknown_key_is_refused() {
    let msg = refused(
        &GOOD.replace("torque_nm = 50.0", "torque_nm = 50.0, torque_nmm = 3.0"),
        "joints[0].limits.torque_nmm",
    );
    assert!(msg.contains("unknown key"), "{msg}");
    refused(
        &GOOD.replace("[robot]", "[robot]\ncolour = \"red\""),
        "robot.colour",
    );
    refused(&format!("{GOOD}\n[extras]\nx = 1\n"), "extras");
}

#[test]
fn wrong_unit_for_the_joint_kind_is_an_unknown_key() {
    refused(
        &GOOD.replace("min_mm = 0.0", "min_deg = 0.0"),
        "joints[1].limits.min_deg",
    );
}

#[test]
fn missing_key_is_refused() {
    let msg = refused(
        &GOOD.replace("alpha_deg = 90.0 }", "}"),
        "joints[0].dh.alpha_deg",
    );
    assert!(msg.contains("missing"), "{msg}");
    refused(
        &GOOD.replace("gravity_mps2 = [0.0, 0.0, -9.81]", ""),
        "robot.gravity_mps2",
    );
    refused(&GOOD.replace("name = \"j2\"\n", ""), "joints[1].name");
}

#[test]
fn non_finite_number_is_refused() {
    let msg = refused(
        &GOOD.replace(
            "a_mm = 0.0, alpha_deg = 90.0",
            "a_mm = nan, alpha_deg = 90.0",
        ),
        "joints[0].dh.a_mm",
    );
    assert!(msg.contains("not a finite number"), "{msg}");
    refused(
        &GOOD.replace("com_mm = [0.0, 0.0, -50.0]", "com_mm = [0.0, inf, -50.0]"),
        "joints[1].link.com_mm[1]",
    );
}

#[test]
fn min_above_max_is_refused() {
    let msg = refused(
        &GOOD.replace("min_deg = -170.0", "min_deg = 175.0"),
        "joints[0].limits.min_deg",
    );
    assert!(msg.contains("175 is above max_deg = 170"), "{msg}");
}

#[test]
fn negative_mass_is_refused() {
    let msg = refused(
        &GOOD.replace("mass_kg = 0.5", "mass_kg = -0.5"),
        "joints[1].link.mass_kg",
    );
    assert!(msg.contains("negative"), "{msg}");
}

#[test]
fn asymmetric_inertia_is_refused() {
    let msg = refused(
        &GOOD.replace(
            "[[50.0, 0.0, 0.0], [0.0, 50.0, 0.0]",
            "[[50.0, 5.0, 0.0], [0.0, 50.0, 0.0]",
        ),
        "joints[1].link.inertia_kgmm2",
    );
    assert!(msg.contains("not symmetric"), "{msg}");
}

#[test]
fn indefinite_inertia_is_refused() {
    let msg = refused(
        &GOOD.replace("[0.0, 0.0, 10.0]] }", "[0.0, 0.0, -10.0]] }"),
        "joints[1].link.inertia_kgmm2",
    );
    assert!(msg.contains("positive semi-definite"), "{msg}");
}

#[test]
fn more_than_eight_joints_is_refused() {
    let start = GOOD.find("[[joints]]").unwrap_or(0);
    let end = GOOD[start + 1..]
        .find("[[joints]]")
        .map_or(GOOD.len(), |i| i + start + 1);
    let block = &GOOD[start..end];
    let mut text = GOOD[..start].to_string();
    for i in 0..9 {
        text += &block.replace("name = \"j1\"", &format!("name = \"j{i}\""));
    }
    let msg = refused(&text, "joints");
    assert!(msg.contains("9 joints"), "{msg}");
}

#[test]
fn no_joints_is_refused() {
    let head = &GOOD[..GOOD.find("[[joints]]").unwrap_or(GOOD.len())];
    refused(head, "joints");
}

#[test]
fn unknown_joint_kind_is_refused() {
    refused(
        &GOOD.replace("kind = \"prismatic\"", "kind = \"spherical\""),
        "joints[1].kind",
    );
}

#[test]
fn wrong_type_is_refused() {
    refused(
        &GOOD.replace("mass_kg = 1.0", "mass_kg = \"heavy\""),
        "joints[0].link.mass_kg",
    );
    refused(
        &GOOD.replace("com_mm = [0.0, 0.0, 0.0]", "com_mm = [0.0, 0.0]"),
        "joints[0].link.com_mm",
    );
}

#[test]
fn duplicate_joint_name_is_refused() {
    refused(
        &GOOD.replace("name = \"j2\"", "name = \"j1\""),
        "joints[1].name",
    );
}

#[test]
fn bad_optional_values_are_refused() {
    refused(
        &GOOD.replace(
            "kind = \"revolute\"",
            "kind = \"revolute\"\ngear_ratio = 0.0",
        ),
        "joints[0].gear_ratio",
    );
    refused(
        &GOOD.replace(
            "kind = \"revolute\"",
            "kind = \"revolute\"\nviscous_friction_nms = -1.0",
        ),
        "joints[0].viscous_friction_nms",
    );
    refused(
        &format!("{GOOD}\n[tool]\nxyz_mm = [0.0, 0.0, 1.0]\n"),
        "tool.rpy_deg",
    );
    refused(
        &format!(
            "{GOOD}\n[payload]\nmass_kg = -1.0\ncom_mm = [0.0, 0.0, 0.0]\ninertia_kgmm2 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n"
        ),
        "payload.mass_kg",
    );
}

#[test]
fn syntax_error_names_the_file() {
    match load("[robot\nname = 1") {
        Err(e @ RobotFileError::Syntax { .. }) => {
            assert!(e.to_string().starts_with("bad-arm.toml: invalid TOML"))
        }
        other => panic!("expected a syntax error, got {other:?}"),
    }
}

#[test]
fn missing_file_names_the_file() {
    match Robot::from_file(std::path::Path::new("/nonexistent/dir/ghost-arm.toml")) {
        Err(e @ RobotFileError::Io { .. }) => {
            assert!(e.to_string().starts_with("ghost-arm.toml: cannot read"))
        }
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn every_shipped_robot_file_loads() {
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/robots"));
    let mut count = 0;
    for entry in std::fs::read_dir(dir).expect("config/robots exists") {
        let path = entry.expect("dir entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
            count += 1;
        }
    }
    assert!(count >= 3, "expected the seed arm and the example robots");
}
