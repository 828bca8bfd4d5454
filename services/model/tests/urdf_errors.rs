//! Malformed URDF files and overlays (`tests/malformed_urdf/`): each is refused
//! with an error naming the file, the element and the joint or link, never a
//! panic. Plus what loads with gaps: the overlay keys a URDF robot lacks, and
//! inertia warnings.

use microrobot_model::{JointKind, Robot, RobotFileError};
use std::path::Path;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/malformed_urdf");

/// File, the key the error names (`None`: a parse error without one), and
/// what the message must say.
const CASES: &[(&str, Option<&str>, &str)] = &[
    ("not_xml.urdf", None, "invalid URDF"),
    ("cycle.urdf", Some("robot"), "no root link"),
    ("duplicate_joint.urdf", Some("joint[j1]"), "used twice"),
    (
        "floating_on_path.urdf",
        Some("joint[j2]"),
        "floating joint on the base→tip path",
    ),
    (
        "planar_on_path.urdf",
        Some("joint[j2]"),
        "planar joint on the base→tip path",
    ),
    ("mimic_on_path.urdf", Some("joint[j2].mimic"), "mimic joint"),
    (
        "indefinite_inertia.urdf",
        Some("link[link1].inertial.inertia"),
        "not positive semi-definite",
    ),
    (
        "inf_inertia.urdf",
        Some("link[link1].inertial.inertia"),
        "not a finite number",
    ),
    (
        "nan_origin.urdf",
        Some("joint[j2].origin.xyz"),
        "NaN is not a finite number",
    ),
    (
        "negative_mass.urdf",
        Some("link[link1].inertial.mass"),
        "negative",
    ),
    (
        "negative_damping.urdf",
        Some("joint[j2].dynamics"),
        "must be >= 0",
    ),
    (
        "missing_inertial.urdf",
        Some("link[link2].inertial"),
        "moves with joint \"j2\"",
    ),
    ("missing_limit.urdf", Some("joint[j2].limit"), "missing"),
    (
        "lower_above_upper.urdf",
        Some("joint[j2].limit.lower"),
        "above upper",
    ),
    ("zero_axis.urdf", Some("joint[j2].axis"), "zero vector"),
    (
        "unknown_link.urdf",
        Some("joint[j2].child"),
        "\"link2\" is not defined",
    ),
    (
        "two_parents.urdf",
        Some("joint[j3].child"),
        "already the child of joint \"j2\"",
    ),
    ("too_many_joints.urdf", Some("robot"), "9 moving joints"),
    ("no_moving_joint.urdf", Some("robot"), "no moving joint"),
    (
        "side_branch.urdf",
        Some("robot"),
        "(joint \"side_joint\" branches off): name tip_link",
    ),
    (
        "no_path.toml",
        Some("robot.tip_link"),
        "no path from base_link \"link2\" to tip_link \"link1\"",
    ),
    (
        "unknown_tip.toml",
        Some("robot.tip_link"),
        "no link \"nowhere\"",
    ),
    ("lock_on_path.toml", Some("lock.j1"), "on the path"),
    (
        "lock_unknown.toml",
        Some("lock.elbow"),
        "no joint \"elbow\"",
    ),
    (
        "lock_outside_limits.toml",
        Some("lock.side_joint"),
        "outside the joint's limits",
    ),
    (
        "unknown_joint.toml",
        Some("joints.side_joint"),
        "a moving joint on the path: j1, j2",
    ),
    ("wrong_unit.toml", Some("joints.j1.acc_mm_s2"), "acc_deg_s2"),
    (
        "nonpositive_limit.toml",
        Some("joints.j1.jerk_deg_s3"),
        "must be > 0",
    ),
    ("missing_urdf.toml", Some("robot.urdf"), "absent.urdf"),
    ("unknown_key.toml", Some("robot.base"), "unknown key"),
];

#[test]
fn every_malformed_file_is_refused_naming_file_element_and_joint() {
    let mut seen = Vec::new();
    for (file, key, says) in CASES {
        let path = Path::new(DIR).join(file);
        let result = std::panic::catch_unwind(|| Robot::from_file(&path));
        let err = match result {
            Err(_) => panic!("{file}: the loader panicked"),
            Ok(Ok(_)) => panic!("{file}: loaded, but it is malformed"),
            Ok(Err(e)) => e,
        };
        let msg = err.to_string();
        assert!(msg.starts_with(&format!("{file}: ")), "{file}: {msg}");
        assert_eq!(err.key(), *key, "{file}: {msg}");
        if let Some(key) = key {
            assert!(msg.contains(key), "{file}: {msg}");
        }
        assert!(
            msg.contains(says),
            "{file}: {msg} (expected to say {says:?})"
        );
        seen.push(file.to_string());
    }
    // Every file of the corpus has its case.
    for entry in std::fs::read_dir(DIR).expect("corpus directory") {
        let name = entry
            .expect("entry")
            .file_name()
            .to_string_lossy()
            .into_owned();
        assert!(seen.contains(&name), "{name} has no case in CASES");
    }
}

#[test]
fn a_urdf_without_rate_limits_loads_and_names_the_missing_overlay_keys() {
    let overlay = "[robot]\nurdf = \"side_branch.urdf\"\ntip_link = \"link2\"\n\
                   [joints.j1]\nvel_deg_s = 90.0\nacc_deg_s2 = 180.0\njerk_deg_s3 = 1800.0\n\
                   rotor_inertia_kgmm2 = 500.0\ngear_ratio = 100.0\n";
    let dir = std::env::temp_dir().join(format!("microrobot-urdf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    std::fs::copy(
        Path::new(DIR).join("side_branch.urdf"),
        dir.join("side_branch.urdf"),
    )
    .expect("copy");
    let path = dir.join("arm.toml");
    std::fs::write(&path, overlay).expect("write overlay");
    let robot = Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(robot.dof(), 2);
    let j1 = &robot.joints()[0];
    assert_eq!(j1.kind, JointKind::Revolute);
    let deg = std::f64::consts::PI / 180.0;
    assert_eq!(j1.limits.velocity, 90.0 * deg);
    assert_eq!(j1.limits.acceleration, 180.0 * deg);
    assert_eq!(j1.limits.jerk, 1800.0 * deg);
    assert_eq!(j1.rotor_inertia, 500.0e-6);
    assert_eq!(j1.gear_ratio, 100.0);
    // From the URDF's <limit>: effort 10, velocity 1 rad/s (j2).
    assert_eq!(j1.limits.effort, 10.0);
    assert_eq!(robot.joints()[1].limits.velocity, 1.0);
    assert!(robot.joints()[1].limits.acceleration.is_nan());
    assert_eq!(
        robot.missing_limits(),
        ["joints.j2.acc_deg_s2", "joints.j2.jerk_deg_s3"]
    );
    // Defaults: gravity along −z of the base, tool frame at the tip link.
    assert_eq!(robot.gravity(), nalgebra::Vector3::new(0.0, 0.0, -9.81));
    assert_eq!(robot.tool(), &microrobot_model::Pose::IDENTITY);
}

#[test]
fn overlay_text_without_its_directory_is_refused() {
    let err = Robot::from_toml_str("[robot]\nurdf = \"x.urdf\"\n", "arm.toml")
        .expect_err("an overlay needs its directory");
    assert!(matches!(err, RobotFileError::Invalid { .. }));
    assert_eq!(err.key(), Some("robot.urdf"));
}

/// The seed arm's link inertias break the triangle inequality: a warning each,
/// and the arm loads.
#[test]
fn triangle_inequality_is_a_warning_not_an_error() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
    let robot = Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
    assert!(!robot.warnings().is_empty());
    for w in robot.warnings() {
        assert!(w.starts_with("seed-arm.toml: joints["), "{w}");
        assert!(w.contains("triangle inequality"), "{w}");
    }
}
