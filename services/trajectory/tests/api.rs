//! The public API's contracts: input errors name joint and field, LSPB refusals,
//! minimum durations, stop, the per-cycle generator.

mod common;
use common::*;
use microrobot_trajectory::{
    Generator, JointVector, MotionRequest, MotionState, Profile, Sample, Status, Trajectory,
    TrajectoryError, minimum_duration, stop_trajectory,
};

fn one(profile: Profile, q0: f64, q1: f64) -> MotionRequest {
    MotionRequest {
        dof: 1,
        start: MotionState::at_rest(jv(&[q0])),
        target: MotionState::at_rest(jv(&[q1])),
        profile,
        limits: limits(&[1.0], &[1.0], &[1.0], 10.0),
    }
}

fn field_of(e: TrajectoryError) -> (usize, &'static str) {
    match e {
        TrajectoryError::NotFinite { joint, field, .. }
        | TrajectoryError::NotPositive { joint, field, .. }
        | TrajectoryError::OutOfRange { joint, field, .. }
        | TrajectoryError::PositionOverrun { joint, field, .. }
        | TrajectoryError::Unsupported { joint, field, .. } => (joint, field),
        TrajectoryError::BadDof(_) => (0, "dof"),
    }
}

const SOFT: Profile = Profile::Soft { min_duration: None };

#[test]
fn bad_input_is_an_error_naming_joint_and_field() {
    let ok = soft_request(
        &[0.0, 0.0],
        &[0.0, 0.0],
        &[0.0, 0.0],
        &[1.0, -1.0],
        limits(&[1.0; 2], &[1.0; 2], &[1.0; 2], 5.0),
    );
    assert!(Trajectory::plan(&ok).is_ok());
    type Edit = Box<dyn Fn(&mut MotionRequest)>;
    let cases: Vec<(Edit, (usize, &str))> = vec![
        (Box::new(|r| r.dof = 0), (0, "dof")),
        (Box::new(|r| r.dof = 9), (0, "dof")),
        (Box::new(|r| r.start.q[1] = f64::NAN), (1, "start.q")),
        (Box::new(|r| r.target.q[1] = f64::INFINITY), (1, "target.q")),
        (
            Box::new(|r| r.limits.velocity[1] = 0.0),
            (1, "limits.velocity"),
        ),
        (
            Box::new(|r| r.limits.acceleration[0] = -1.0),
            (0, "limits.acceleration"),
        ),
        (
            Box::new(|r| r.limits.jerk[1] = f64::NAN),
            (1, "limits.jerk"),
        ),
        (Box::new(|r| r.target.q[1] = -6.0), (1, "target.q")),
        (Box::new(|r| r.start.q[0] = 7.0), (0, "start.q")),
        (Box::new(|r| r.start.qd[1] = 1.5), (1, "start.qd")),
        (Box::new(|r| r.start.qdd[0] = -2.0), (0, "start.qdd")),
        (
            Box::new(|r| {
                r.profile = Profile::Soft {
                    min_duration: Some(-1.0),
                }
            }),
            (0, "profile.min_duration"),
        ),
        (
            Box::new(|r| r.profile = Profile::Cubic { duration: 0.0 }),
            (0, "profile.duration"),
        ),
        (
            Box::new(|r| r.profile = Profile::Quintic { duration: f64::NAN }),
            (0, "profile.duration"),
        ),
    ];
    for (k, (edit, want)) in cases.iter().enumerate() {
        let mut r = ok;
        edit(&mut r);
        let e = Trajectory::plan(&r).expect_err(&format!("case {k} must fail"));
        assert_eq!(field_of(e), *want, "case {k}: {e}");
    }
}

#[test]
fn braking_past_a_position_limit_is_an_error() {
    // Moving at 0.9 rad/s towards the +1 limit from 0.8: no stop fits.
    let mut r = one(SOFT, 0.8, 0.9);
    r.limits = limits(&[1.0], &[1.0], &[1.0], 1.0);
    r.start.qd[0] = 0.9;
    let e = Trajectory::plan(&r).expect_err("overruns");
    assert!(
        matches!(
            e,
            TrajectoryError::PositionOverrun {
                joint: 0,
                field: "limits.position_max",
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn lspb_refuses_cruise_velocities_outside_the_interval() {
    let with = |v: f64| {
        Trajectory::plan(&one(
            Profile::Lspb {
                duration: 2.0,
                cruise_velocity: Some(jv(&[v])),
            },
            0.0,
            1.0,
        ))
    };
    // |q1 - q0|/T = 0.5 < |V| <= 1.0 = 2|q1 - q0|/T, with the sign of q1 - q0.
    for v in [0.5, 0.2, 1.01, -0.75, 0.0] {
        let e = with(v).expect_err(&format!("V = {v} refused"));
        assert_eq!(field_of(e), (0, "profile.cruise_velocity"));
    }
    for v in [0.51, 0.75, 1.0] {
        assert!(with(v).is_ok(), "V = {v} accepted");
    }
    // Default 1.5·(q1 − q0)/T, also for q1 < q0; q1 = q0 holds still.
    let down = Trajectory::plan(&one(
        Profile::Lspb {
            duration: 2.0,
            cruise_velocity: None,
        },
        1.0,
        0.0,
    ))
    .expect("plans");
    assert_close(down.sample(1.0).qd[0], -0.75, 1e-12, "default cruise");
    let still = Trajectory::plan(&one(
        Profile::Lspb {
            duration: 2.0,
            cruise_velocity: None,
        },
        0.3,
        0.3,
    ))
    .expect("plans");
    assert_eq!(still.sample(1.0).q[0], 0.3);
}

#[test]
fn minimum_duration_respects_the_limits_each_profile_can_honour() {
    // Seed: the rest-to-rest cubic needs 6h/T² ≤ amax → T = √(6h/amax) (v: 1.5h/T).
    let (h, a) = (2.0 * std::f64::consts::PI, 80f64.to_radians());
    let mut r = one(
        Profile::Cubic { duration: 1.0 },
        -std::f64::consts::PI,
        std::f64::consts::PI,
    );
    r.limits = limits(&[135f64.to_radians()], &[a], &[160f64.to_radians()], 4.0);
    let t = minimum_duration(&r).expect("cubic");
    assert_close(
        t,
        (6.0 * h / a).sqrt().max(1.5 * h / 135f64.to_radians()),
        1e-9,
        "cubic",
    );
    // Quintic: v 1.875h/T, a 5.7735h/T², jerk 60h/T³.
    r.profile = Profile::Quintic { duration: 1.0 };
    let tq = minimum_duration(&r).expect("quintic");
    let (v, j) = (135f64.to_radians(), 160f64.to_radians());
    let want = (1.875 * h / v)
        .max((10.0 / 3f64.sqrt() * h / a).sqrt())
        .max((60.0 * h / j).cbrt());
    assert_close(tq, want, 1e-9, "quintic");
    r.profile = Profile::Soft { min_duration: None };
    assert_close(
        minimum_duration(&r).expect("soft"),
        4.854166666666667,
        1e-12,
        "soft",
    );
}

#[test]
fn stop_brings_every_joint_to_rest_independently() {
    let lim = limits(&[1.0, 2.0], &[1.0, 1.0], &[2.0, 2.0], 100.0);
    let s = MotionState {
        q: jv(&[0.0, 1.0]),
        qd: jv(&[0.8, -1.5]),
        qdd: jv(&[0.5, 0.0]),
    };
    let tr = stop_trajectory(2, &s, &lim).expect("stops");
    let end = tr.sample(tr.duration());
    assert_eq!(
        (end.qd[0], end.qd[1], end.qdd[0], end.qdd[1]),
        (0.0, 0.0, 0.0, 0.0)
    );
    // 0.8 + 0.5²/(2·2) = 0.8625 < vmax: no brake pre-phase needed.
    assert!(!tr.braked());
    // 0.95 + 0.9²/4 > vmax = 1: the stop brakes first.
    let fast = MotionState {
        qd: jv(&[0.95, 0.0]),
        qdd: jv(&[0.9, 0.0]),
        ..s
    };
    assert!(stop_trajectory(2, &fast, &lim).expect("stops").braked());
    assert!(matches!(
        stop_trajectory(0, &s, &lim),
        Err(TrajectoryError::BadDof(0))
    ));
}

#[test]
fn generator_steps_and_replans_without_jumps() {
    let tr = Trajectory::plan(&one(SOFT, 0.0, 1.0)).expect("plans");
    let mut g = Generator::new(tr);
    let dt = 1e-3;
    let mut last = g.current();
    let mut n = 0;
    loop {
        let (status, s) = g.update(dt);
        n += 1;
        if n == 500 {
            // Replan from the current sample to a new target: the stream continues.
            let mut r = one(SOFT, 0.0, -0.5);
            r.start = s.state();
            g.replace(Trajectory::plan(&r).expect("replans"));
            let again = g.current();
            assert_eq!((again.q, again.qd, again.qdd), (s.q, s.qd, s.qdd));
        }
        assert!((s.q[0] - last.q[0]).abs() <= dt * 1.0 + 1e-12);
        last = s;
        if status == Status::Finished {
            break;
        }
    }
    assert_eq!(g.at(1e9).0, Status::Finished);
    assert_eq!(last.q[0], -0.5);
    let copy: Trajectory = *g.trajectory(); // Copy, no heap.
    assert_eq!(copy.sample(0.25), g.trajectory().sample(0.25));
}

#[test]
fn in_place_stepping_equals_stepping_by_value_and_overwrites_every_lane() {
    let tr = Trajectory::plan(&one(SOFT, 0.0, 1.0)).expect("plans");
    let (mut by_value, mut in_place) = (Generator::new(tr), Generator::new(tr));
    // A kept sample full of garbage: every lane must be written (zero past dof).
    let mut out = Sample {
        q: JointVector::repeat(f64::NAN),
        qd: JointVector::repeat(7.0),
        qdd: JointVector::repeat(-3.0),
        jerk: JointVector::repeat(f64::INFINITY),
    };
    for _ in 0..1500 {
        let (status, s) = by_value.update(1e-3);
        assert_eq!(in_place.update_into(1e-3, &mut out), status);
        for (a, b) in [
            (s.q, out.q),
            (s.qd, out.qd),
            (s.qdd, out.qdd),
            (s.jerk, out.jerk),
        ] {
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
    }
    assert_eq!(in_place.at_into(1e9, &mut out), Status::Finished);
    assert_eq!(out.q[0], 1.0);
    assert!(out.q.iter().skip(1).all(|&x| x == 0.0));
}

#[test]
fn generator_cached_sampling_equals_plain_sampling_in_any_order() {
    let req = soft_request(
        &[0.0, 1.0],
        &[0.3, -0.2],
        &[0.1, 0.0],
        &[2.0, -1.0],
        limits(&[1.0, 2.0], &[1.0, 1.5], &[2.0, 3.0], 10.0),
    );
    let tr = Trajectory::plan(&req).expect("plans");
    let mut g = Generator::new(tr);
    let d = tr.duration();
    // Forward, backward, past the end, negative, NaN-free jumps.
    for &f in &[
        0.1, 0.5, 0.49, 0.9, 0.2, 1.5, 0.95, -0.1, 0.0, 0.3, 0.31, 0.05, 1.0,
    ] {
        let t = f * d;
        assert_eq!(g.at(t).1, tr.sample(t), "at {t}");
    }
}

#[test]
fn synchronised_motion_with_a_braking_joint_stays_within_limits_after_the_brake() {
    // Joint 0 is about to cross vmax (0.9 + 0.8²/(2·1) > 1); joint 1 starts at rest.
    let lim = limits(&[1.0, 1.0], &[1.0, 1.0], &[1.0, 1.0], 20.0);
    let req = soft_request(&[0.0, 0.0], &[0.9, 0.0], &[0.8, 0.0], &[-2.0, 0.5], lim);
    let tr = Trajectory::plan(&req).expect("plans");
    assert!(tr.braked());
    let n = 20_000;
    let mut peak = 0.0f64;
    for k in 0..=n {
        let s = tr.sample(tr.duration() * k as f64 / n as f64);
        peak = peak.max(s.qd[0].abs());
        assert!(s.qd[0].abs() <= 0.9 + 0.8 * 0.8 / 2.0 + 1e-9);
        assert!(s.qd[1].abs() <= 1.0 + 1e-9 && s.qdd[1].abs() <= 1.0 + 1e-9);
        assert!(s.qdd[0].abs() <= 1.0 + 1e-9 && s.jerk[0].abs() <= 1.0 + 1e-9);
    }
    assert!(peak > 1.0, "the unavoidable overshoot happens");
    let end = tr.sample(tr.duration());
    assert_eq!(
        (end.q[0], end.q[1], end.qd[0], end.qd[1]),
        (-2.0, 0.5, 0.0, 0.0)
    );
    // Both joints still move just before the common end.
    let late = tr.sample(tr.duration() * 0.99);
    assert!(late.qd[0].abs() > 0.0 && late.qd[1].abs() > 0.0);
}

/// `sample_into` writes exactly what `sample` returns, lanes past `dof` included (zero),
/// into a `Sample` that held anything before: soft (moving start), quintic, and after
/// the end.
#[test]
fn sample_into_equals_sample_whatever_the_buffer_held() {
    let lim = limits(&[1.0, 2.0, 0.5], &[1.0, 3.0, 2.0], &[2.0, 5.0, 1.0], 10.0);
    let soft = soft_request(
        &[0.0, 1.0, -1.0],
        &[0.3, -0.2, 0.0],
        &[0.1, 0.0, -0.4],
        &[1.0, -1.0, 0.5],
        lim,
    );
    let mut quintic = soft;
    quintic.profile = Profile::Quintic { duration: 3.0 };
    let mut out = microrobot_trajectory::Sample::default();
    for req in [soft, quintic] {
        let tr = Trajectory::plan(&req).expect("plans");
        for k in -2..=62 {
            let t = tr.duration() * k as f64 / 60.0;
            for v in [&mut out.q, &mut out.qd, &mut out.qdd, &mut out.jerk] {
                v.fill(7.0);
            }
            tr.sample_into(t, &mut out);
            assert_eq!(out, tr.sample(t), "t = {t}");
            assert!(out.q.as_slice()[3..].iter().all(|&x| x == 0.0));
        }
    }
}
