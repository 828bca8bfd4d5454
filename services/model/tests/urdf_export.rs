//! `to_urdf` + `overlay_toml` round trip: a robot written as URDF and loaded back
//! through its overlay is the same robot — the tool pose, the tool Jacobian, the mass
//! matrix, gravity and the full inverse dynamics (rotor inertia and friction included)
//! agree at random states to 1e-9 relative (1e-12 absolute). DH robots (revolute and
//! prismatic) and a placed robot loaded from URDF alike.

use std::path::{Path, PathBuf};

use microrobot_model::{
    JointVector, ModelData, Robot, gravity_torque, jacobian, mass_matrix, overlay_toml, rnea,
    to_urdf, tool_pose,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Writes `robot` as `<dir>/arm.urdf` + `<dir>/arm.toml` and loads the overlay.
fn round_trip(robot: &Robot, dir: &Path) -> Robot {
    std::fs::write(dir.join("arm.urdf"), to_urdf(robot)).expect("write urdf");
    let overlay = dir.join("arm.toml");
    std::fs::write(&overlay, overlay_toml(robot, "arm.urdf")).expect("write overlay");
    Robot::from_file(&overlay).unwrap_or_else(|e| panic!("load back: {e}"))
}

/// A small deterministic generator (no dependency): uniform in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn close(a: f64, b: f64, what: &str) {
    let tol = 1e-12 + 1e-9 * a.abs().max(b.abs());
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b}");
}

fn same_robot(a: &Robot, b: &Robot) {
    assert_eq!(a.dof(), b.dof());
    assert_eq!(a.name(), b.name());
    for (ja, jb) in a.joints().iter().zip(b.joints()) {
        assert_eq!(ja.name, jb.name);
        assert_eq!(ja.kind, jb.kind);
        for (x, y, w) in [
            (ja.limits.min, jb.limits.min, "min"),
            (ja.limits.max, jb.limits.max, "max"),
            (ja.limits.velocity, jb.limits.velocity, "velocity"),
            (
                ja.limits.acceleration,
                jb.limits.acceleration,
                "acceleration",
            ),
            (ja.limits.jerk, jb.limits.jerk, "jerk"),
            (ja.limits.effort, jb.limits.effort, "effort"),
            (ja.rotor_inertia, jb.rotor_inertia, "rotor inertia"),
            (ja.gear_ratio, jb.gear_ratio, "gear ratio"),
            (ja.viscous_friction, jb.viscous_friction, "viscous friction"),
            (ja.coulomb_friction, jb.coulomb_friction, "coulomb friction"),
        ] {
            close(x, y, &format!("{} {w}", ja.name));
        }
    }
    let (mut da, mut db) = (ModelData::new(a), ModelData::new(b));
    let mut rng = Lcg(7);
    for k in 0..50 {
        let mut q = JointVector::zeros();
        let mut qd = JointVector::zeros();
        let mut qdd = JointVector::zeros();
        for (i, j) in a.joints().iter().enumerate() {
            let (lo, hi) = (j.limits.min.max(-3.0), j.limits.max.min(3.0));
            q[i] = lo + (hi - lo) * rng.next();
            qd[i] = (2.0 * rng.next() - 1.0) * j.limits.velocity.min(3.0);
            qdd[i] = 2.0 * rng.next() - 1.0;
        }
        let ctx = |w: &str| format!("state {k}: {w}");
        let (pa, pb) = (tool_pose(a, &mut da, &q), tool_pose(b, &mut db, &q));
        for r in 0..3 {
            close(pa.translation[r], pb.translation[r], &ctx("tool position"));
            for c in 0..3 {
                close(
                    pa.rotation[(r, c)],
                    pb.rotation[(r, c)],
                    &ctx("tool rotation"),
                );
            }
        }
        let (ja, jb) = (jacobian(a, &mut da, &q), jacobian(b, &mut db, &q));
        for (x, y) in ja.iter().zip(jb.iter()) {
            close(*x, *y, &ctx("jacobian"));
        }
        let (ma, mb) = (mass_matrix(a, &mut da, &q), mass_matrix(b, &mut db, &q));
        for (x, y) in ma.iter().zip(mb.iter()) {
            close(*x, *y, &ctx("mass matrix"));
        }
        let (ga, gb) = (
            gravity_torque(a, &mut da, &q),
            gravity_torque(b, &mut db, &q),
        );
        for (x, y) in ga.iter().zip(gb.iter()) {
            close(*x, *y, &ctx("gravity"));
        }
        let ta = rnea(a, &mut da, &q, &qd, &qdd);
        let tb = rnea(b, &mut db, &q, &qd, &qdd);
        for (x, y) in ta.iter().zip(tb.iter()) {
            close(*x, *y, &ctx("inverse dynamics"));
        }
    }
}

#[test]
fn the_seed_arm_as_urdf_is_the_same_robot() {
    let robot = Robot::from_file(&repo().join("config/robots/seed-arm.toml")).expect("seed arm");
    let dir = tempfile::tempdir().expect("tempdir");
    let back = round_trip(&robot, dir.path());
    same_robot(&robot, &back);
    assert!(
        back.missing_limits().is_empty(),
        "{:?}",
        back.missing_limits()
    );
}

#[test]
fn a_dh_robot_with_a_prismatic_joint_as_urdf_is_the_same_robot() {
    for file in ["spherical-rrp.toml", "planar-2r.toml"] {
        let robot = Robot::from_file(&repo().join("config/robots").join(file)).expect(file);
        let dir = tempfile::tempdir().expect("tempdir");
        same_robot(&robot, &round_trip(&robot, dir.path()));
    }
}

#[test]
fn a_urdf_robot_written_again_is_the_same_robot() {
    let robot = Robot::from_file(&repo().join("config/robots/panda.toml")).expect("panda");
    let dir = tempfile::tempdir().expect("tempdir");
    same_robot(&robot, &round_trip(&robot, dir.path()));
}

#[test]
fn the_urdf_names_every_joint_and_link_and_escapes_names() {
    let robot = Robot::from_file(&repo().join("config/robots/seed-arm.toml")).expect("seed arm");
    let text = to_urdf(&robot);
    for j in robot.joints() {
        assert!(text.contains(&format!("<joint name=\"{}\" type=\"revolute\">", j.name)));
        assert!(text.contains(&format!("<link name=\"{}_link\">", j.name)));
    }
    assert!(text.contains("<link name=\"tool\"/>"));
    assert!(text.contains("<cylinder"), "links have a visual");
}
