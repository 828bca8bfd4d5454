//! Motion programs: parsing (units, unknown keys), planning with continuity, the
//! seed's Table 4 program, Cartesian targets through the solver trait.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;
use microrobot_trajectory::program::{
    CartesianPose, CartesianSolver, NoCartesian, Program, ProgramError, ProgramRunner,
};
use microrobot_trajectory::{JointVector, KinematicLimits, MotionState, Status};

fn file(name: &str) -> String {
    let path = format!(
        "{}/../../config/programs/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The seed arm's limits (config/robots/seed-arm.toml).
fn seed_arm() -> KinematicLimits {
    let d = |x: f64| x.to_radians();
    let mut l = limits(
        &[135.0, 70.0, 70.0, 135.0, 70.0, 135.0].map(d),
        &[80.0, 40.0, 40.0, 80.0, 40.0, 80.0].map(d),
        &[160.0, 80.0, 80.0, 160.0, 80.0, 160.0].map(d),
        0.0,
    );
    for (i, (lo, hi)) in [
        (-180.0, 180.0),
        (-90.0, 90.0),
        (0.0, 180.0),
        (-180.0, 180.0),
        (-90.0, 90.0),
        (-180.0, 180.0),
    ]
    .into_iter()
    .enumerate()
    {
        l.position_min[i] = d(lo);
        l.position_max[i] = d(hi);
    }
    l
}

/// Runs a plan at 1 kHz and checks continuity of q, qd (and qdd) between cycles.
fn run_continuous(
    runner: &mut ProgramRunner,
    lim: &KinematicLimits,
    smooth: bool,
) -> (MotionState, f64) {
    let dt = 1e-3;
    let mut prev = runner.update(0.0).1;
    let mut t = 0.0;
    loop {
        let (status, s) = runner.update(dt);
        t += dt;
        for i in 0..6 {
            assert!(
                (s.q[i] - prev.q[i]).abs() <= lim.velocity[i] * dt * 1.001 + 1e-12,
                "q jumps at {t}"
            );
            assert!(
                (s.qd[i] - prev.qd[i]).abs() <= lim.acceleration[i] * dt * 1.001 + 1e-9,
                "qd jumps at {t}"
            );
            if smooth {
                assert!(
                    (s.qdd[i] - prev.qdd[i]).abs() <= lim.jerk[i] * dt * 1.001 + 1e-9,
                    "qdd jumps at {t}"
                );
            }
        }
        prev = s;
        if status == Status::Finished {
            return (s.state(), t);
        }
        assert!(t < 100.0, "never finishes");
    }
}

#[test]
fn seed_table4_program_finishes_together_at_5_s() {
    let p = Program::from_toml_str(&file("seed-table4.toml"), "seed-table4.toml").expect("loads");
    assert_eq!((p.dof, p.segments.len()), (6, 2));
    let lim = seed_arm();
    let plan = p
        .plan_all(&MotionState::default(), &lim, &NoCartesian)
        .expect("plans");
    let main = &plan[1].trajectory;
    assert_close(main.duration(), 5.0, 1e-12, "tf");
    main.check_limits(&lim, true).expect("within limits");
    let want: [f64; 6] = [180.0, 90.0, 180.0, 180.0, 90.0, 180.0];
    let end = main.sample(5.0);
    for i in 0..6 {
        assert_close(end.q[i], want[i].to_radians(), 1e-12, "theta_f");
        assert_eq!(end.qd[i], 0.0);
        // Every joint still moves until the end: they finish together.
        assert!(
            main.sample(4.9).qd[i].abs() > 1e-6,
            "joint {i} finished early"
        );
    }
    let mut runner = ProgramRunner::new(plan).expect("segments");
    let (last, _) = run_continuous(&mut runner, &lim, true);
    assert_close(last.q[2], 180f64.to_radians(), 1e-12, "end");
}

#[test]
fn blended_quintic_via_points_are_continuous_and_pass_through() {
    let p = Program::from_toml_str(&file("via-points-blend.toml"), "via").expect("loads");
    let lim = seed_arm();
    let plan = p
        .plan_all(&MotionState::default(), &lim, &NoCartesian)
        .expect("plans");
    // Quintics do not honour the jerk limit: bound the per-cycle changes by the peaks.
    let mut bounds = lim;
    for seg in &plan {
        let pk = seg.trajectory.peaks();
        for i in 0..6 {
            bounds.velocity[i] = bounds.velocity[i].max(pk.velocity[i]);
            bounds.acceleration[i] = bounds.acceleration[i].max(pk.acceleration[i]);
            bounds.jerk[i] = bounds.jerk[i].max(pk.jerk[i]);
        }
    }
    let via = plan[0].trajectory.sample(2.0);
    assert!(
        via.qd.iter().any(|v| v.abs() > 1e-3),
        "passes the via point moving"
    );
    assert_close(via.q[0], 0.0, 1e-12, "via q");
    let mut runner = ProgramRunner::new(plan).expect("segments");
    assert_close(runner.duration(), 6.5, 1e-12, "total");
    let (end, t) = run_continuous(&mut runner, &bounds, true);
    assert!((t - 6.5).abs() < 2e-3, "finished at {t}");
    assert_close(end.q[5], 45f64.to_radians(), 1e-12, "goal");
}

#[test]
fn soft_blend_hands_over_while_moving() {
    let p = Program::from_toml_str(&file("soft-blend.toml"), "soft").expect("loads");
    let lim = seed_arm();
    let plan = p
        .plan_all(&MotionState::default(), &lim, &NoCartesian)
        .expect("plans");
    assert_close(
        plan[0].hand_over,
        plan[0].trajectory.duration() - 0.4,
        1e-12,
        "hand-over",
    );
    let handed = plan[0].trajectory.sample(plan[0].hand_over);
    let next = plan[1].trajectory.sample(0.0);
    assert!(handed.qd.iter().any(|v| v.abs() > 1e-3));
    assert_eq!(
        (handed.q, handed.qd, handed.qdd),
        (next.q, next.qd, next.qdd)
    );
    let mut runner = ProgramRunner::new(plan).expect("segments");
    let (end, _) = run_continuous(&mut runner, &lim, true);
    assert_close(end.q[5], 45f64.to_radians(), 1e-12, "goal");
}

#[test]
fn unknown_keys_and_bad_values_are_errors_naming_the_key() {
    let base = "[program]\nname = \"x\"\ndof = 2\n[[segment]]\nq_deg = [1.0, 2.0]\n";
    assert!(Program::from_toml_str(base, "ok").is_ok());
    let e =
        Program::from_toml_str(&format!("{base}speed = 3\n"), "f.toml").expect_err("unknown key");
    assert!(
        e.to_string().contains("speed") && e.to_string().contains("f.toml"),
        "{e}"
    );
    let e = Program::from_toml_str(&format!("{base}profile = \"cubic\"\n"), "f")
        .expect_err("no duration");
    assert!(e.to_string().contains("duration_s"), "{e}");
    let e =
        Program::from_toml_str(&format!("{base}duration_s = -1.0\n"), "f").expect_err("negative");
    assert!(e.to_string().contains("duration_s"), "{e}");
    let e = Program::from_toml_str(
        "[program]\nname = \"x\"\ndof = 2\n[[segment]]\nq_deg = [1.0]\n",
        "f",
    )
    .expect_err("short");
    assert!(e.to_string().contains("q_deg"), "{e}");
    let e = Program::from_toml_str(
        &format!("{base}profile = \"lspb\"\nduration_s = 1.0\nend = \"blend\"\n"),
        "f",
    )
    .expect_err("lspb blend");
    assert!(e.to_string().contains("end"), "{e}");
    // Degrees are converted once at load.
    let p = Program::from_toml_str(base, "ok").expect("loads");
    match p.segments[0].target {
        microrobot_trajectory::program::Target::Joint(q) => {
            assert_close(q[1], 2f64.to_radians(), 1e-15, "rad")
        }
        _ => panic!("joint target"),
    }
}

#[test]
fn targets_outside_the_limits_fail_with_the_segment() {
    let text =
        "[program]\nname = \"x\"\ndof = 6\n[[segment]]\nq_deg = [0.0, 0.0, -10.0, 0.0, 0.0, 0.0]\n";
    let p = Program::from_toml_str(text, "f").expect("loads");
    let start = MotionState::at_rest(jv(&[0.0, 0.0, 0.1, 0.0, 0.0, 0.0]));
    let e = p
        .plan_all(&start, &seed_arm(), &NoCartesian)
        .expect_err("joint 3 below 0");
    assert!(matches!(e, ProgramError::Plan { segment: 0, .. }), "{e}");
    assert!(
        e.to_string().contains("joint[2]") && e.to_string().contains("target.q"),
        "{e}"
    );
}

struct FakeIk;
impl CartesianSolver for FakeIk {
    fn solve(&self, pose: &CartesianPose, seed: &JointVector) -> Result<JointVector, String> {
        if pose.xyz_m[0] > 1.0 {
            return Err("out of reach".into());
        }
        let mut q = *seed;
        q[0] = pose.xyz_m[0];
        q[2] = pose.rpy_rad[2].abs();
        Ok(q)
    }
}

#[test]
fn cartesian_targets_go_through_the_solver() {
    let text = "[program]\nname = \"c\"\ndof = 6\n[[segment]]\npose = { xyz_mm = [100.0, 0.0, 0.0], rpy_deg = [0.0, 0.0, 30.0] }\n";
    let p = Program::from_toml_str(text, "c").expect("loads");
    let start = MotionState::at_rest(jv(&[0.0, 0.0, 0.1, 0.0, 0.0, 0.0]));
    let plan = p.plan_all(&start, &seed_arm(), &FakeIk).expect("plans");
    let end = plan[0].trajectory.sample(1e9);
    assert_close(end.q[0], 0.1, 1e-15, "xyz_mm converted");
    assert_close(end.q[2], 30f64.to_radians(), 1e-15, "rpy_deg converted");
    let far = text.replace("100.0", "2000.0");
    let e = Program::from_toml_str(&far, "c")
        .expect("loads")
        .plan_all(&start, &seed_arm(), &FakeIk)
        .expect_err("unreachable");
    assert!(matches!(e, ProgramError::Ik { segment: 0, .. }), "{e}");
}

#[test]
fn units_follow_the_joint_type_and_a_mismatch_names_key_and_joint() {
    use microrobot_model::JointKind::{Prismatic, Revolute};
    use microrobot_trajectory::program::Target;
    let rrp = [Revolute, Revolute, Prismatic];
    let seg = |key: &str| {
        format!("[program]\nname = \"u\"\ndof = 3\n[[segment]]\n{key} = [90.0, 45.0, 200.0]\n")
    };
    let joint = |p: &Program| match p.segments[0].target {
        Target::Joint(q) => q,
        _ => panic!("joint target"),
    };
    // Each joint in its type's unit, converted once at load.
    let p = Program::from_toml_str_for(&seg("q_deg_mm"), "rrp.toml", &rrp).expect("loads");
    let q = joint(&p);
    assert_close(q[0], 90f64.to_radians(), 1e-15, "deg");
    assert_close(q[2], 0.2, 1e-15, "mm");
    let p = Program::from_toml_str_for(&seg("q_rad_m"), "rrp.toml", &rrp).expect("loads");
    assert_close(joint(&p)[2], 200.0, 1e-12, "m");
    // An angle key on a prismatic joint, a length key on a revolute one.
    for (key, joint_no, wants) in [("q_deg", 3, "length"), ("q_mm", 1, "angle")] {
        let e = Program::from_toml_str_for(&seg(key), "rrp.toml", &rrp)
            .expect_err("unit does not fit")
            .to_string();
        assert!(
            e.contains("rrp.toml")
                && e.contains(&format!("{key}:"))
                && e.contains(&format!("joint {joint_no}"))
                && e.contains(wants),
            "{e}"
        );
    }
    // An all-prismatic target in mm.
    let text = "[program]\nname = \"p\"\ndof = 1\n[[segment]]\nq_mm = [150.0]\n";
    let p = Program::from_toml_str_for(text, "p.toml", &[Prismatic]).expect("loads");
    assert_close(joint(&p)[0], 0.15, 1e-15, "mm");
    // Limits in degrees do not fit a prismatic joint.
    let limited = format!(
        "{}[limits]\nvel_deg_s = 10.0\nacc_deg_s2 = 10.0\njerk_deg_s3 = 10.0\n",
        seg("q_deg_mm")
    );
    let e = Program::from_toml_str_for(&limited, "rrp.toml", &rrp)
        .expect_err("degree limits on a prismatic joint")
        .to_string();
    assert!(e.contains("limits") && e.contains("joint 3"), "{e}");
    // The joint count must match the robot's.
    let e = Program::from_toml_str_for(&seg("q_deg_mm"), "rrp.toml", &rrp[..2])
        .expect_err("dof")
        .to_string();
    assert!(e.contains("program.dof"), "{e}");
}
