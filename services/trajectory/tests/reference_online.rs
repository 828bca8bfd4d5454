//! Ruckig 0.19.4 online cases: single-joint time-optimal motion from a moving state
//! (durations and samples) and 6-joint synchronised durations.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;
use microrobot_trajectory::{KinematicLimits, Trajectory};

/// The keys one reference file names a single-joint case's fields with.
struct SingleKeys {
    q0: &'static str,
    q1: &'static str,
    q: &'static str,
    qd: &'static str,
    qdd: &'static str,
}

/// Plans one joint of case `c` (limits `vmax`, `amax`, `jmax`, start `v0`, `a0`) and
/// holds its duration and its samples at `t_s` to Ruckig's to 1e-9.
fn plan_and_match_ruckig(
    c: &serde_json::Value,
    k: &SingleKeys,
    what: &str,
) -> (Trajectory, KinematicLimits) {
    let lim = limits(&[f(&c["vmax"])], &[f(&c["amax"])], &[f(&c["jmax"])], 1e3);
    let req = soft_request(
        &[f(&c[k.q0])],
        &[f(&c["v0"])],
        &[f(&c["a0"])],
        &[f(&c[k.q1])],
        lim,
    );
    let tr = Trajectory::plan(&req).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_close(
        tr.duration(),
        f(&c["duration_s"]),
        1e-9,
        &format!("{what} duration"),
    );
    let t = fs(&c["t_s"]);
    for (field, want) in [
        (k.q, fs(&c[k.q])),
        (k.qd, fs(&c[k.qd])),
        (k.qdd, fs(&c[k.qdd])),
    ] {
        for (i, &ti) in t.iter().enumerate() {
            let x = tr.sample(ti);
            let got = if field == k.q {
                x.q[0]
            } else if field == k.qd {
                x.qd[0]
            } else {
                x.qdd[0]
            };
            assert!(
                (got - want[i]).abs() < 1e-9 * (1.0 + want[i].abs()),
                "{what} {field} at {ti}: {got} vs Ruckig's {}",
                want[i]
            );
        }
    }
    (tr, lim)
}

#[test]
fn single_joint_from_moving_state_matches_ruckig() {
    let r = load("online_trajectory_reference.json");
    let keys = SingleKeys {
        q0: "p0",
        q1: "p1",
        q: "position",
        qd: "velocity",
        qdd: "acceleration",
    };
    for (n, c) in r["single"].as_array().expect("single").iter().enumerate() {
        let kind = c["kind"].as_str().expect("kind");
        let (tr, lim) = plan_and_match_ruckig(c, &keys, &format!("case {n} ({kind})"));
        assert!(!tr.braked(), "case {n} ({kind}) braked");
        tr.check_limits(&lim, true)
            .unwrap_or_else(|e| panic!("case {n}: {e}"));
    }
}

#[test]
fn synchronised_six_joints_match_ruckig_durations() {
    let r = load("online_trajectory_reference.json");
    for (n, c) in r["synchronized"]
        .as_array()
        .expect("synchronized")
        .iter()
        .enumerate()
    {
        let lim = limits(
            &fs(&c["vmax"]),
            &fs(&c["amax"]),
            &fs(&c["jmax"]),
            std::f64::consts::PI + 0.5,
        );
        let req = soft_request(
            &fs(&c["p0"]),
            &fs(&c["v0"]),
            &fs(&c["a0"]),
            &fs(&c["p1"]),
            lim,
        );
        let tr = Trajectory::plan(&req).unwrap_or_else(|e| panic!("case {n}: {e}"));
        assert_close(
            tr.duration(),
            f(&c["duration_s"]),
            1e-9,
            &format!("case {n} duration"),
        );
        // Every joint: limits honoured and the exact end state; the limiting joint
        // also matches Ruckig's samples (the others are one valid choice among many).
        tr.check_limits(&lim, true)
            .unwrap_or_else(|e| panic!("case {n}: {e}"));
        let p1 = fs(&c["p1"]);
        let end = tr.sample(tr.duration());
        for i in 0..6 {
            assert_close(end.q[i], p1[i], 1e-12, "end q");
            assert_eq!((end.qd[i], end.qdd[i]), (0.0, 0.0));
        }
        let lj = c["limiting_joint"].as_u64().expect("limiting joint") as usize - 1;
        let t = fs(&c["t_s"]);
        for (k, &tk) in t.iter().enumerate() {
            let want = f(&c["position"][k][lj]);
            assert!(
                (tr.sample(tk).q[lj] - want).abs() < 1e-9,
                "case {n} limiting joint q at {tk}"
            );
        }
        for (i, &tmin) in fs(&c["independent_min_durations_s"]).iter().enumerate() {
            assert!(tr.duration() >= tmin - 1e-9, "case {n} joint {i}");
        }
    }
}

/// From states bound to cross vmax, Ruckig brakes back under vmax as fast as the jerk
/// limit allows (ending early if the stop velocity reaches −vmax), then plans
/// time-optimally: durations and samples, including those inside the brake.
#[test]
fn braking_from_a_state_bound_to_cross_vmax_matches_ruckig() {
    let r = load("ruckig_brake_reference.json");
    let cases = r["cases"].as_array().expect("cases");
    assert!(cases.len() >= 50, "{} cases", cases.len());
    let keys = SingleKeys {
        q0: "q0",
        q1: "q1",
        q: "q",
        qd: "qd",
        qdd: "qdd",
    };
    for (n, c) in cases.iter().enumerate() {
        let (tr, _) = plan_and_match_ruckig(c, &keys, &format!("case {n}"));
        assert!(tr.braked(), "case {n} did not brake");
    }
}

/// Synchronised problems where one non-limiting joint's target lies just past its brake
/// point, found by comparing 80 000 random problems with Ruckig (the stretch family
/// alone came out 0.2–20 % longer on them): Ruckig's common duration is reached. Every
/// joint ends exactly at rest on its target with |a| ≤ amax, and |v| ≤ vmax except for
/// the unavoidable overshoot of a joint that has to brake.
#[test]
fn synchronised_durations_with_a_joint_just_past_its_brake_point_match_ruckig() {
    let r = load("ruckig_sync_reference.json");
    let cases = r["reached"].as_array().expect("reached");
    assert!(cases.len() >= 40, "{} cases", cases.len());
    for (n, c) in cases.iter().enumerate() {
        let (vm, am, jm) = (fs(&c["vmax"]), fs(&c["amax"]), fs(&c["jmax"]));
        let (q0, v0, a0, q1) = (fs(&c["q0"]), fs(&c["v0"]), fs(&c["a0"]), fs(&c["q1"]));
        let lim = limits(&vm, &am, &jm, 1e3);
        let tr = Trajectory::plan(&soft_request(&q0, &v0, &a0, &q1, lim))
            .unwrap_or_else(|e| panic!("case {n}: {e}"));
        assert_close(
            tr.duration(),
            f(&c["duration_s"]),
            1e-9,
            &format!("case {n} duration"),
        );
        let end = tr.sample(tr.duration());
        for i in 0..q0.len() {
            assert_close(end.q[i], q1[i], 1e-12, "end q");
            assert_eq!((end.qd[i], end.qdd[i]), (0.0, 0.0), "case {n} joint {i}");
        }
        let steps = 4000;
        for k in 0..=steps {
            let x = tr.sample(tr.duration() * k as f64 / steps as f64);
            for i in 0..q0.len() {
                let v_bound = vm[i].max((v0[i] + a0[i] * a0[i].abs() / (2.0 * jm[i])).abs());
                assert!(
                    x.qdd[i].abs() <= am[i] * (1.0 + 1e-9),
                    "case {n} joint {i} a"
                );
                assert!(
                    x.qd[i].abs() <= v_bound * (1.0 + 1e-9),
                    "case {n} joint {i} v"
                );
            }
        }
    }
}
