//! The torque law, clamping, feedback selection and input validation of the dynamics core.

use std::path::PathBuf;

use microrobot_dynamics::{DynamicsConfig, DynamicsCore};
use microrobot_messages::{Header, JointSetpoint, JointState, state_flags, torque_flags};
use microrobot_model::{JointVector, ModelData, Robot, mass_matrix, nonlinear_effects, rnea};
use microrobot_runtime::config::PipelineConfig;

const MS: u64 = 1_000_000;

fn cfg(lockstep: bool) -> PipelineConfig {
    PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        lockstep,
        ..Default::default()
    }
}

fn sp(seq: u64, stamp: u64, q: [f64; 6], qdd: [f64; 6]) -> JointSetpoint {
    let mut s = JointSetpoint {
        header: Header {
            seq,
            tick: seq,
            stamp_ns: stamp,
            source_stamp_ns: stamp,
        },
        dof: 6,
        ..Default::default()
    };
    s.q[..6].copy_from_slice(&q);
    s.qdd[..6].copy_from_slice(&qdd);
    s
}

fn state(seq: u64, tick: u64, stamp: u64, q: [f64; 6]) -> JointState {
    let mut s = JointState {
        header: Header {
            seq,
            tick,
            stamp_ns: stamp,
            source_stamp_ns: stamp,
        },
        dof: 6,
        ..Default::default()
    };
    s.q[..6].copy_from_slice(&q);
    s
}

const Q: [f64; 6] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6];

#[test]
fn on_the_setpoint_at_rest_feedback_equals_inverse_dynamics() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    let now = 1000 * MS;
    d.accept_state(&state(1, 0, now, Q), 9, 0).unwrap();
    let t = d.compute(&sp(1, now, Q, [0.0; 6]), 1, now).unwrap();
    assert_ne!(t.flags & torque_flags::FEEDBACK, 0);
    let q = JointVector::from_column_slice(&[Q[0], Q[1], Q[2], Q[3], Q[4], Q[5], 0.0, 0.0]);
    let z = JointVector::zeros();
    let g = rnea(&robot, &mut ModelData::new(&robot), &q, &z, &z);
    for i in 0..6 {
        assert!(
            (t.tau[i] - g[i]).abs() < 1e-9,
            "joint {i}: {} vs {}",
            t.tau[i],
            g[i]
        );
    }
    assert_eq!(t.state_seq, 1);
    assert_eq!(t.q_desired[..6], Q);
}

/// Off the setpoint and moving, the torque is the computed-torque law
/// `M(q)(q̈d + Kp(qd − q) + Kd(q̇d − q̇)) + h(q, q̇)`, here formed with the mass matrix and
/// the nonlinear effects, which the core evaluates in one Newton-Euler pass instead.
#[test]
fn off_the_setpoint_feedback_is_the_computed_torque_law() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let gains = DynamicsConfig {
        delay_compensation: false,
        ..DynamicsConfig::default()
    };
    let mut d = DynamicsCore::new(&robot, &c, &gains);
    let now = 1000 * MS;
    let mut s = state(1, 0, now, Q);
    let v = [0.3, -0.2, 0.25, -0.4, 0.5, -0.6];
    s.qd[..6].copy_from_slice(&v);
    d.accept_state(&s, 9, 0).unwrap();
    let q_sp = [0.101, 0.199, 0.3015, 0.398, 0.5, 0.601];
    let (vd, ad) = (
        [0.31, -0.21, 0.24, -0.41, 0.52, -0.58],
        [0.5, -1.0, 0.8, 1.2, -0.7, 0.3],
    );
    let mut p = sp(1, now, q_sp, ad);
    p.qd[..6].copy_from_slice(&vd);
    let t = d.compute(&p, 1, now).unwrap();
    assert_ne!(t.flags & torque_flags::FEEDBACK, 0);
    assert_eq!(t.flags & torque_flags::CLAMPED, 0, "{:?}", t.tau);
    let col = |x: [f64; 6]| {
        JointVector::from_column_slice(&[x[0], x[1], x[2], x[3], x[4], x[5], 0.0, 0.0])
    };
    let (q, qdot) = (col(Q), col(v));
    let mut a = JointVector::zeros();
    for i in 0..6 {
        a[i] = ad[i] + gains.kp_per_s2 * (q_sp[i] - Q[i]) + gains.kd_per_s * (vd[i] - v[i]);
    }
    let mut data = ModelData::new(&robot);
    let m = mass_matrix(&robot, &mut data, &q);
    let expected = m * a + nonlinear_effects(&robot, &mut data, &q, &qdot);
    for i in 0..6 {
        assert!(
            (t.tau[i] - expected[i]).abs() <= 1e-9 * expected[i].abs().max(1.0),
            "joint {i}: {} vs {}",
            t.tau[i],
            expected[i]
        );
    }
}

#[test]
fn stale_state_gives_flagged_feed_forward() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    let now = 1000 * MS;
    d.accept_state(&state(1, 0, now - 60 * MS, Q), 9, 0)
        .unwrap();
    let t = d.compute(&sp(1, now, Q, [0.0; 6]), 1, now).unwrap();
    assert_ne!(t.flags & torque_flags::STATE_STALE, 0);
    assert_eq!(t.state_seq, u64::MAX);
    assert_eq!(d.counters.stale_cycles, 1);
}

#[test]
fn lockstep_uses_only_state_k_minus_1() {
    let c = cfg(true);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    d.accept_state(&state(1, 4, 0, Q), 9, 0).unwrap();
    let t = d.compute(&sp(5, 0, Q, [0.0; 6]), 1, 0).unwrap();
    assert_ne!(t.flags & torque_flags::FEEDBACK, 0);
    let t = d.compute(&sp(7, 0, Q, [0.0; 6]), 1, 0).unwrap();
    assert_ne!(
        t.flags & torque_flags::STATE_STALE,
        0,
        "state 4 is not state 6"
    );
}

#[test]
fn lockstep_feedback_ignores_the_actuators_final_state() {
    // The final state repeats the last period's tick with the brakes on (here: a
    // different q). Whether it arrives before or after the next setpoint, that setpoint
    // gets the same torque, computed from the state of the running arm.
    let c = cfg(true);
    let robot = Robot::from_file(&c.robot).unwrap();
    let torque = |final_first: bool| {
        let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
        d.accept_state(&state(1, 4, 0, Q), 9, 0).unwrap();
        let mut last = state(2, 4, 0, [0.0; 6]);
        last.flags = state_flags::FINAL;
        if final_first {
            d.accept_state(&last, 9, 0).unwrap();
        }
        let t = d.compute(&sp(5, 0, Q, [0.0; 6]), 1, 0).unwrap();
        if !final_first {
            d.accept_state(&last, 9, 0).unwrap();
        }
        t
    };
    let (a, b) = (torque(true), torque(false));
    assert_ne!(a.flags & torque_flags::FEEDBACK, 0);
    assert_eq!(a.state_seq, 1, "the running arm's state, not the final one");
    assert_eq!(a.flags, b.flags);
    assert_eq!(a.tau, b.tau);
}

#[test]
fn torques_beyond_the_effort_limit_are_clamped_and_flagged() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    let now = 1000 * MS;
    d.accept_state(&state(1, 0, now, Q), 9, 0).unwrap();
    let t = d.compute(&sp(1, now, Q, [500.0; 6]), 1, now).unwrap();
    assert_ne!(t.flags & torque_flags::CLAMPED, 0);
    for i in 0..6 {
        assert!(t.tau[i].abs() <= robot.joints()[i].limits.effort);
    }
    assert_eq!(d.counters.clamped_cycles, 1);
}

#[test]
fn bad_setpoints_get_no_torque() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    let now = 1000 * MS;
    let mut nan = sp(1, now, Q, [0.0; 6]);
    nan.qd[3] = f64::NAN;
    assert!(d.compute(&nan, 1, now).is_err());
    assert!(
        d.compute(
            &sp(2, now, [0.1, 0.2, -0.3, 0.4, 0.5, 0.6], [0.0; 6]),
            1,
            now
        )
        .is_err(),
        "joint 3 below 0"
    );
    assert!(
        d.compute(&sp(3, now - 80 * MS, Q, [0.0; 6]), 1, now)
            .is_err(),
        "stale"
    );
    assert!(d.compute(&sp(4, now, Q, [0.0; 6]), 1, now).is_ok());
    assert!(
        d.compute(&sp(4, now, Q, [0.0; 6]), 1, now).is_err(),
        "duplicate"
    );
    assert_eq!(d.counters.refused, 4);
    assert_eq!(d.counters.cycles, 1);
}

/// A host stall: the free-running arm kept moving open-loop while the pipeline was held,
/// so the next state is 30 ms away from where the plan is. Feedback would answer with a
/// torque step; the slew limit turns it into a ramp of τmax·Δt/torque_slew_ms per tick,
/// flagged, and the torque still reaches the unlimited value once the ramp has run.
#[test]
fn a_state_that_jumped_gives_a_torque_ramp_not_a_step() {
    let c = cfg(false);
    let robot = Robot::from_file(&c.robot).unwrap();
    let mut d = DynamicsCore::new(&robot, &c, &DynamicsConfig::default());
    let dynamics = DynamicsConfig::default();
    let mut free = DynamicsCore::new(
        &robot,
        &c,
        &DynamicsConfig {
            torque_slew_ms: 0.0,
            ..dynamics.clone()
        },
    );
    let now = 1000 * MS;
    d.accept_state(&state(1, 0, now, Q), 9, 0).unwrap();
    let first = d.compute(&sp(1, now, Q, [0.0; 6]), 1, now).unwrap();
    assert_eq!(first.flags & torque_flags::SLEW_LIMITED, 0);
    // The arm sagged 0.02 rad on every joint while nothing ran.
    let sagged = Q.map(|q| q - 0.02);
    let per_tick: Vec<f64> = robot
        .joints()
        .iter()
        .map(|j| j.limits.effort / (dynamics.torque_slew_ms * 1e-3 * c.rate_hz))
        .collect();
    free.accept_state(&state(1, 1, now, sagged), 9, 0).unwrap();
    let wanted = free.compute(&sp(2, now, Q, [0.0; 6]), 1, now).unwrap();
    let mut prev = first;
    for k in 2..40u64 {
        d.accept_state(&state(k, k - 1, now, sagged), 9, 0).unwrap();
        let t = d.compute(&sp(k, now, Q, [0.0; 6]), 1, now).unwrap();
        for (i, max) in per_tick.iter().enumerate() {
            let step = (t.tau[i] - prev.tau[i]).abs();
            assert!(
                step <= max * (1.0 + 1e-12),
                "tick {k} joint {i}: step {step} > {max}"
            );
        }
        if k == 2 {
            assert_ne!(t.flags & torque_flags::SLEW_LIMITED, 0, "the step is cut");
        }
        prev = t;
    }
    for i in 0..6 {
        assert!(
            (prev.tau[i] - wanted.tau[i]).abs() < 1e-9,
            "joint {i}: ramp ends at {} not {}",
            prev.tau[i],
            wanted.tau[i]
        );
    }
    assert!(d.counters.slew_limited_cycles >= 1);
}
