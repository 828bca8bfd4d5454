//! Cartesian program targets through the robot model's IK, and limits from a robot file.

use microrobot_model::{ModelData, Robot, tool_pose};
use microrobot_trajectory::model::ModelIk;
use microrobot_trajectory::program::Program;
use microrobot_trajectory::{JointVector, KinematicLimits, MotionState};
use nalgebra::Rotation3;

fn seed_arm() -> Robot {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/robots/seed-arm.toml"
    );
    let text = std::fs::read_to_string(path).expect("robot file");
    Robot::from_toml_str(&text, path).expect("seed arm loads")
}

#[test]
fn limits_come_from_the_robot_file() {
    let robot = seed_arm();
    let l = KinematicLimits::from_robot(&robot);
    assert!((l.velocity[0] - 135f64.to_radians()).abs() < 1e-12);
    assert!(
        (l.position_min[2] - 0.0).abs() < 1e-12
            && (l.position_max[2] - 180f64.to_radians()).abs() < 1e-12
    );
}

#[test]
fn cartesian_target_is_reached_through_the_model_ik() {
    let robot = seed_arm();
    let mut data = ModelData::new(&robot);
    let goal = JointVector::from_column_slice(&[0.3, -0.4, 1.2, 0.2, 0.5, -0.3, 0.0, 0.0]);
    let pose = tool_pose(&robot, &mut data, &goal);
    let (r, p, y) = Rotation3::from_matrix(&pose.rotation).euler_angles();
    let t = pose.translation * 1e3;
    let text = format!(
        "[program]\nname = \"ik\"\ndof = 6\n[[segment]]\npose = {{ xyz_mm = [{}, {}, {}], rpy_deg = [{}, {}, {}] }}\n",
        t.x,
        t.y,
        t.z,
        r.to_degrees(),
        p.to_degrees(),
        y.to_degrees()
    );
    let program = Program::from_toml_str(&text, "ik").expect("loads");
    let mut start = MotionState::default();
    start.q[2] = 1.0;
    let plan = program
        .plan_all(
            &start,
            &KinematicLimits::from_robot(&robot),
            &ModelIk::new(&robot),
        )
        .expect("plans");
    let end = plan[0].trajectory.sample(f64::INFINITY);
    let reached = tool_pose(&robot, &mut data, &end.q);
    assert!(
        (reached.translation - pose.translation).norm() < 1e-6,
        "position"
    );
    assert!(
        (reached.rotation - pose.rotation).norm() < 1e-6,
        "orientation"
    );
}
