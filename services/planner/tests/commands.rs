//! Motion commands: every field validated, refused commands never move the arm, and a
//! replan mid-motion continues the setpoint stream without a jump.

use std::path::PathBuf;

use microrobot_messages::{
    CommandKind, JointSetpoint, JointState, MotionCommand, ProfileKind, TargetSpace,
};
use microrobot_model::Robot;
use microrobot_planner::{CommandError, Mode, PlannerCore};
use microrobot_runtime::config::PipelineConfig;

fn setup() -> PlannerCore {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let mut p = PlannerCore::new(&robot, &cfg, None);
    let s = JointState {
        dof: 6,
        header: microrobot_messages::Header {
            seq: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(p.accept_state(&s, 1, 0));
    p
}

fn mv(target: [f64; 6], profile: ProfileKind, duration_s: f64) -> MotionCommand {
    let mut c = MotionCommand {
        kind: CommandKind::Move as u32,
        profile: profile as u32,
        space: TargetSpace::Joint as u32,
        dof: 6,
        duration_s,
        ..Default::default()
    };
    c.target[..6].copy_from_slice(&target);
    c
}

fn cmd(kind: CommandKind) -> MotionCommand {
    MotionCommand {
        kind: kind as u32,
        ..Default::default()
    }
}

const T: [f64; 6] = [0.5, 0.3, 0.2, 0.4, 0.3, -0.5];

#[test]
fn bad_commands_are_refused_and_do_not_move_the_arm() {
    let mut p = setup();
    let mut nan = mv(T, ProfileKind::Soft, 0.0);
    nan.target[2] = f64::NAN;
    let mut wrong_dof = mv(T, ProfileKind::Soft, 0.0);
    wrong_dof.dof = 5;
    let mut unknown = mv(T, ProfileKind::Soft, 0.0);
    unknown.kind = 42;
    let mut bad_profile = mv(T, ProfileKind::Soft, 0.0);
    bad_profile.profile = 9;
    let mut bad_scale = mv(T, ProfileKind::Soft, 0.0);
    bad_scale.limit_scale = 1.5;
    let mut inf_duration = mv(T, ProfileKind::Cubic, 1.0);
    inf_duration.duration_s = f64::INFINITY;
    let cases = [
        (nan, "non-finite target"),
        (wrong_dof, "wrong dof"),
        (unknown, "unknown kind"),
        (bad_profile, "unknown profile"),
        (bad_scale, "limit scale"),
        (inf_duration, "infinite duration"),
        (
            mv([0.5, 0.3, -0.2, 0.4, 0.3, -0.5], ProfileKind::Soft, 0.0),
            "joint 3 below its 0° limit",
        ),
        (mv(T, ProfileKind::Cubic, 0.0), "cubic without duration"),
        (
            mv(T, ProfileKind::Cubic, 0.01),
            "impossible duration (exceeds the velocity limit)",
        ),
        (mv(T, ProfileKind::Quintic, -1.0), "negative duration"),
    ];
    for (c, what) in cases {
        assert!(p.on_command(&c, 1).is_err(), "{what} was accepted");
    }
    assert_eq!(p.counters.commands_refused, 10);
    assert_eq!(p.counters.commands_accepted, 0);
    for _ in 0..100 {
        let sp = p.tick(1);
        assert!(sp.q.iter().all(|&q| q == 0.0) && sp.qd.iter().all(|&v| v == 0.0));
    }
}

#[test]
fn stale_commands_are_refused() {
    let mut p = setup();
    let mut c = mv(T, ProfileKind::Soft, 0.0);
    c.stamp_ns = 1;
    assert!(matches!(
        p.on_command(&c, 10_000_000_000),
        Err(CommandError::Stale { .. })
    ));
}

fn max_step(a: &JointSetpoint, b: &JointSetpoint) -> (f64, f64) {
    let dq = (0..6).map(|i| (a.q[i] - b.q[i]).abs()).fold(0.0, f64::max);
    let dqd = (0..6)
        .map(|i| (a.qd[i] - b.qd[i]).abs())
        .fold(0.0, f64::max);
    (dq, dqd)
}

#[test]
fn a_move_mid_motion_replans_without_a_jump() {
    let mut p = setup();
    p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1).unwrap();
    let mut prev = p.tick(1);
    for _ in 0..1500 {
        prev = p.tick(1);
    }
    assert!(
        prev.qd.iter().any(|v| v.abs() > 0.05),
        "moving at the switch"
    );
    p.on_command(
        &mv([-0.3, 0.1, 0.5, 0.0, -0.2, 0.3], ProfileKind::Soft, 0.0),
        1,
    )
    .unwrap();
    let next = p.tick(1);
    let (dq, dqd) = max_step(&prev, &next);
    // One period at ≤ 2.4 rad/s moves ≤ 2.4 mrad; acceleration ≤ 1.4 rad/s² changes qd ≤ 1.4 mrad/s.
    assert!(dq < 3e-3, "position step {dq}");
    assert!(dqd < 2e-3, "velocity step {dqd}");
    let dqdd = (0..6)
        .map(|i| (prev.qdd[i] - next.qdd[i]).abs())
        .fold(0.0, f64::max);
    assert!(dqdd < 0.01, "soft motion keeps qdd continuous: step {dqdd}");
}

#[test]
fn estop_brakes_and_refuses_motion_until_reset() {
    let mut p = setup();
    p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1).unwrap();
    for _ in 0..1500 {
        p.tick(1);
    }
    p.on_command(&cmd(CommandKind::EStop), 1).unwrap();
    assert_eq!(p.mode(), Mode::EStop);
    assert!(matches!(
        p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1),
        Err(CommandError::EStopActive)
    ));
    let mut last = p.tick(1);
    for _ in 0..5000 {
        last = p.tick(1);
    }
    assert!(last.qd.iter().all(|v| *v == 0.0), "at rest after the brake");
    p.on_command(&cmd(CommandKind::Reset), 1).unwrap();
    assert_eq!(p.mode(), Mode::Hold);
    p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1).unwrap();
}

#[test]
fn stop_brings_the_arm_to_rest() {
    let mut p = setup();
    p.on_command(&mv(T, ProfileKind::Quintic, 4.0), 1).unwrap();
    for _ in 0..1000 {
        p.tick(1);
    }
    p.on_command(&cmd(CommandKind::Stop), 1).unwrap();
    let mut last = p.tick(1);
    for _ in 0..5000 {
        last = p.tick(1);
    }
    assert!(last.qd.iter().all(|v| *v == 0.0));
    assert!(p.program_done());
}

/// The reset handshake: a Reset in the actuator's safe state resumes the planner only
/// once the actuator reports that it has left that state (the same Reset reaches both,
/// in either order), so the planner never stays behind following a resumed arm.
#[test]
fn a_reset_in_the_safe_state_resumes_when_the_actuator_does() {
    let mut p = setup();
    let state = |seq: u64, safe: bool| JointState {
        dof: 6,
        flags: if safe {
            microrobot_messages::state_flags::SAFE_STATE
        } else {
            0
        },
        header: microrobot_messages::Header {
            seq,
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(p.accept_state(&state(2, true), 1, 0));
    p.check_state(0);
    assert_eq!(p.mode(), Mode::SafeHold);
    assert!(p.on_command(&cmd(CommandKind::Reset), 0).is_ok());
    // The actuator has not processed the reset yet: still following it.
    assert!(p.accept_state(&state(3, true), 1, 0));
    p.check_state(0);
    p.tick(0);
    assert_eq!(p.mode(), Mode::SafeHold);
    assert_eq!(
        p.on_command(&mv(T, ProfileKind::Soft, 0.0), 0),
        Err(CommandError::SafeStateActive)
    );
    // Now it has: the planner resumes (a jerk-limited stop from the measured state).
    assert!(p.accept_state(&state(4, false), 1, 0));
    p.check_state(0);
    assert_ne!(p.mode(), Mode::SafeHold);
    assert!(p.on_command(&mv(T, ProfileKind::Soft, 0.0), 0).is_ok());
}

/// A restarted planner that finds the arm moving starts from its measured velocity (a
/// jerk-limited stop from there), not at rest: no velocity jump in the setpoint stream.
/// Finding the actuator in its safe state, it mirrors the arm from the first tick.
#[test]
fn a_planner_starting_on_a_moving_arm_continues_from_its_measured_velocity() {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let mut moving = JointState {
        dof: 6,
        header: microrobot_messages::Header {
            seq: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    moving.q[0] = 0.2;
    moving.qd[0] = 0.3;
    let mut p = PlannerCore::new(&robot, &cfg, None);
    assert!(p.accept_state(&moving, 1, 0));
    let sp = p.tick(0);
    let amax = robot.joints()[0].limits.acceleration;
    assert!((sp.qd[0] - 0.3).abs() <= amax * 1e-3 * 1.01, "{sp:?}");
    assert!((sp.q[0] - 0.2).abs() <= 0.3 * 1e-3 * 1.01, "{sp:?}");
    assert_eq!(p.mode(), Mode::Stopping);

    moving.flags = microrobot_messages::state_flags::SAFE_STATE;
    let mut p = PlannerCore::new(&robot, &cfg, None);
    assert!(p.accept_state(&moving, 1, 0));
    let sp = p.tick(0);
    assert_eq!(p.mode(), Mode::SafeHold);
    assert_ne!(
        sp.flags & microrobot_messages::setpoint_flags::HOLD_FOR_SAFE_STATE,
        0
    );
    assert_eq!(sp.qd[0], 0.3);
}

/// One master device drives the arm: a second publisher's samples are refused while the
/// followed device is live, and it takes over only after `master_timeout_ms` of silence.
#[test]
fn a_second_master_device_is_refused_while_the_first_is_live() {
    let mut p = setup();
    let ms = 1_000_000u64;
    let t0 = 10_000 * ms;
    let pose = |stamp_ns: u64| microrobot_messages::MasterPose {
        stamp_ns,
        orientation: [1.0, 0.0, 0.0, 0.0],
        ..Default::default()
    };
    assert!(p.on_master(&pose(t0), 1, t0));
    assert!(
        !p.on_master(&pose(t0 + ms), 2, t0 + ms),
        "second device, first live"
    );
    assert!(p.on_master(&pose(t0 + 2 * ms), 1, t0 + 2 * ms));
    // 50 ms (the default master_timeout_ms) after the first device's last sample.
    let later = t0 + 2 * ms + 50 * ms;
    assert!(!p.on_master(&pose(later - 1), 2, later - 1));
    assert!(
        p.on_master(&pose(later), 2, later),
        "takes over after the timeout"
    );
    assert!(
        !p.on_master(&pose(later + ms), 1, later + ms),
        "now the first is the second"
    );
    let c = &p.teleop().counters;
    assert_eq!((c.samples, c.refused, c.second_device), (3, 3, 3));
}

/// The largest velocity and acceleration steps of a jerk-limited stream, per joint, as
/// the limits allow them in one period (1 % slack for rounding).
fn continuity_violation(
    robot: &Robot,
    a: &JointSetpoint,
    b: &JointSetpoint,
    period_s: f64,
) -> Option<String> {
    for (j, joint) in robot.joints().iter().enumerate() {
        let l = &joint.limits;
        let dqd = (b.qd[j] - a.qd[j]).abs();
        let dqdd = (b.qdd[j] - a.qdd[j]).abs();
        if dqd > l.acceleration * period_s * 1.01 + 1e-12 {
            return Some(format!(
                "joint {}: velocity step {} -> {} rad/s",
                j + 1,
                a.qd[j],
                b.qd[j]
            ));
        }
        if dqdd > l.jerk * period_s * 1.01 + 1e-12 {
            return Some(format!(
                "joint {}: acceleration step {} -> {} rad/s²",
                j + 1,
                a.qdd[j],
                b.qdd[j]
            ));
        }
    }
    None
}

fn seed_robot() -> Robot {
    Robot::from_file(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
    )
    .unwrap()
}

/// A Reset while the e-stop still brakes does not cut the brake short (that stepped the
/// setpoint velocity to zero in one tick): the brake runs to rest, motion stays refused
/// until then, and the e-stop lifts at rest.
#[test]
fn a_reset_during_the_estop_brake_lets_the_brake_finish() {
    // Far enough for joint 3 to be near its top speed (~1 rad/s) at the e-stop.
    const FAR: [f64; 6] = [1.5, 1.2, 1.5, 1.5, 1.2, -1.5];
    let robot = seed_robot();
    let mut p = setup();
    p.on_command(&mv(FAR, ProfileKind::Soft, 0.0), 1).unwrap();
    let mut prev = p.tick(1);
    for _ in 0..2000 {
        prev = p.tick(1);
    }
    assert!(prev.qd[2] > 0.8, "joint 3 at speed: {:?}", prev.qd);
    p.on_command(&cmd(CommandKind::EStop), 1).unwrap();
    for _ in 0..300 {
        prev = p.tick(1);
    }
    assert!(
        prev.qd[2] > 0.5,
        "still braking 0.3 s into the e-stop: {:?}",
        prev.qd
    );
    p.on_command(&cmd(CommandKind::Reset), 1).unwrap();
    assert_eq!(p.mode(), Mode::EStop, "the brake goes on");
    assert_eq!(
        p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1),
        Err(CommandError::EStopActive)
    );
    let mut ticks = 0;
    while p.mode() == Mode::EStop {
        let sp = p.tick(1);
        if let Some(v) = continuity_violation(&robot, &prev, &sp, 1e-3) {
            panic!("tick {ticks} after the reset: {v}");
        }
        prev = sp;
        ticks += 1;
        assert!(ticks < 10_000, "the brake never finished");
    }
    assert!(
        ticks > 100,
        "the brake ran on after the reset ({ticks} ticks)"
    );
    assert_eq!(p.mode(), Mode::Hold);
    assert!(prev.qd.iter().chain(&prev.qdd).all(|v| *v == 0.0));
    p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1).unwrap();

    // An e-stop after the reset, still braking, needs a reset of its own.
    let mut p = setup();
    p.on_command(&mv(T, ProfileKind::Soft, 0.0), 1).unwrap();
    for _ in 0..1500 {
        p.tick(1);
    }
    p.on_command(&cmd(CommandKind::EStop), 1).unwrap();
    p.tick(1);
    p.on_command(&cmd(CommandKind::Reset), 1).unwrap();
    p.on_command(&cmd(CommandKind::EStop), 1).unwrap();
    for _ in 0..10_000 {
        p.tick(1);
    }
    assert_eq!(p.mode(), Mode::EStop, "the second e-stop holds until reset");
}

/// A flood of random commands (moves, stops, e-stops, resets at random ticks) keeps the
/// setpoint velocity and acceleration continuous within the limits.
#[test]
fn a_flood_of_random_commands_keeps_the_setpoints_continuous() {
    let robot = seed_robot();
    let mut p = setup();
    // xorshift64*: reproducible without a dependency.
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    };
    let mut prev = p.tick(1);
    let (mut accepted, mut resets_while_braking) = (0, 0);
    for k in 0..20_000 {
        if next() % 20 == 0 {
            let c = match next() % 4 {
                0 => {
                    let mut target = [0.0; 6];
                    for (t, joint) in target.iter_mut().zip(robot.joints()) {
                        let u = (next() >> 11) as f64 / (1u64 << 53) as f64;
                        let l = &joint.limits;
                        *t = l.min + 0.1 + u * (l.max - l.min - 0.2);
                    }
                    mv(target, ProfileKind::Soft, 0.0)
                }
                1 => cmd(CommandKind::Stop),
                2 => cmd(CommandKind::EStop),
                _ => {
                    if p.mode() == Mode::EStop && prev.qd.iter().any(|v| *v != 0.0) {
                        resets_while_braking += 1;
                    }
                    cmd(CommandKind::Reset)
                }
            };
            accepted += p.on_command(&c, 1).is_ok() as u32;
        }
        let sp = p.tick(1);
        if let Some(v) = continuity_violation(&robot, &prev, &sp, 1e-3) {
            panic!("tick {k}: {v}");
        }
        prev = sp;
    }
    assert!(accepted > 50, "{accepted} commands accepted");
    assert!(
        resets_while_braking > 3,
        "{resets_while_braking} resets while braking"
    );
}

/// Resuming after a reset from a measured arm that moves towards a joint limit (it
/// sagged while its drives were off): the stop from there stays within every joint's
/// range (the dynamics refuses a setpoint outside it, and the actuator would get no
/// torque); the joint that would leave it stops at once where it is, the others brake
/// from their measured velocity.
#[test]
fn a_resume_towards_a_joint_limit_stops_within_the_range() {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let mut p = PlannerCore::new(&robot, &cfg, None);
    // As measured in an EtherCAT fault test: joint 6 (range ±π) 0.02 rad from its
    // limit at 1.09 rad/s towards it, joint 5 falling at 0.64 rad/s mid-range.
    let q = [
        3.141569, -1.570791, 0.000009, -3.141579, -0.176718, -3.122121,
    ];
    let qd = [
        0.000466, -0.000222, -0.004398, -0.000190, -0.635701, -1.089624,
    ];
    let state = |seq: u64, safe: bool| {
        let mut s = JointState {
            dof: 6,
            flags: if safe {
                microrobot_messages::state_flags::SAFE_STATE
            } else {
                0
            },
            header: microrobot_messages::Header {
                seq,
                ..Default::default()
            },
            ..Default::default()
        };
        s.q[..6].copy_from_slice(&q);
        s.qd[..6].copy_from_slice(&qd);
        s
    };
    assert!(p.accept_state(&state(1, true), 1, 0));
    p.check_state(0);
    assert_eq!(p.mode(), Mode::SafeHold);
    assert!(p.on_command(&cmd(CommandKind::Reset), 0).is_ok());
    assert!(p.accept_state(&state(2, false), 1, 0));
    p.check_state(0);
    assert_ne!(p.mode(), Mode::SafeHold, "resumed");
    let joints = robot.joints();
    let mut first = None;
    for k in 0..2000 {
        let sp = p.tick(0);
        for (i, j) in joints.iter().enumerate() {
            assert!(
                j.limits.contains(sp.q[i]),
                "tick {k}: joint {} at {} outside [{}, {}]",
                i + 1,
                sp.q[i],
                j.limits.min,
                j.limits.max
            );
        }
        first.get_or_insert(sp);
    }
    let first = first.unwrap();
    // Joint 6 stops where it is; joint 5 brakes from its measured velocity.
    assert_eq!(first.qd[5], 0.0);
    assert!((first.qd[4] - qd[4]).abs() < 0.01, "{}", first.qd[4]);
}
