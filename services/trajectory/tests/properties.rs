//! Property tests over random problems: exact endpoints, continuity, limits,
//! time-optimal structure of soft motion, braking, synchronisation.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;
use microrobot_trajectory::soft::stretch::Stretch;
use microrobot_trajectory::soft::velocity::{ramp, ramp_from_rest};
use microrobot_trajectory::soft::{Kin, Limits1, from_state, rest_to_rest, stop_velocity};
use microrobot_trajectory::{MotionRequest, MotionState, Profile, Trajectory, stop_trajectory};
use proptest::prelude::*;

/// Walks the trajectory on a fine grid and checks that q, qd (and qdd when
/// `smooth`) change no faster than the limits allow: continuity plus limits.
fn check_walk(
    tr: &Trajectory,
    dof: usize,
    lim: &[[f64; 3]],
    smooth: bool,
    skip: f64,
) -> Result<(), TestCaseError> {
    let n = 3000;
    let h = tr.duration() / n as f64;
    let mut prev = tr.sample(0.0);
    for k in 1..=n + 10 {
        let t = h * k as f64;
        let s = tr.sample(t);
        for i in 0..dof {
            let [v, a, j] = lim[i];
            let tol = 1e-7;
            if t > skip + h {
                prop_assert!(
                    s.qd[i].abs() <= v * (1.0 + 1e-9) + 1e-12,
                    "|qd| {} > {v} at {t}",
                    s.qd[i]
                );
                prop_assert!(
                    s.qdd[i].abs() <= a * (1.0 + 1e-9) + 1e-12,
                    "|qdd| {} > {a} at {t}",
                    s.qdd[i]
                );
                prop_assert!(s.jerk[i].abs() <= j * (1.0 + 1e-9), "|jerk| at {t}");
            }
            let vb = prev.qd[i].abs().max(s.qd[i].abs()) + a.max(prev.qdd[i].abs()) * h;
            prop_assert!(
                (s.q[i] - prev.q[i]).abs() <= vb * h * (1.0 + tol) + 1e-12,
                "q jumps at {t}"
            );
            let ab = prev.qdd[i].abs().max(s.qdd[i].abs()) + j * h;
            prop_assert!(
                (s.qd[i] - prev.qd[i]).abs() <= ab * h * (1.0 + tol) + 1e-12,
                "qd jumps at {t}"
            );
            if smooth {
                prop_assert!(
                    (s.qdd[i] - prev.qdd[i]).abs() <= j * h * (1.0 + tol) + 1e-12,
                    "qdd jumps at {t}"
                );
            }
        }
        prev = s;
    }
    Ok(())
}

/// Limits [v, a, j], start [q, v, a], target q.
type Problem = ([f64; 3], [f64; 3], f64);

prop_compose! {
    /// Limits and a start state that is inside them and will not cross vmax.
    fn joint_problem()(v in 0.2f64..5.0, a in 0.2f64..5.0, j in 0.2f64..20.0,
                       fv in -1.0f64..1.0, fa in -1.0f64..1.0,
                       q0 in -3.0f64..3.0, q1 in -3.0f64..3.0, rest in prop::bool::weighted(0.2))
                       -> ([f64; 3], [f64; 3], f64) {
        // |a0|²/(2j) < 2·vmax leaves room for a v0 with |v0 + a0|a0|/(2j)| < vmax.
        let a0 = if rest { 0.0 } else { fa * a.min(0.99 * (4.0 * j * v).sqrt()) };
        // Keep |v0 + a0|a0|/(2j)| < vmax so no brake is needed.
        let v0 = if rest { 0.0 } else {
            let lo = (-v).max(-v - a0 * a0.abs() / (2.0 * j)) ;
            let hi = v.min(v - a0 * a0.abs() / (2.0 * j));
            lo + (fv * 0.5 + 0.5) * (hi - lo) * 0.999
        };
        ([v, a, j], [q0, v0, a0], q1)
    }
}

/// Independent oracle for the durations one joint can be stretched to: a dense scan
/// of the stretch family (velocity change to a peak velocity vp, cruise, ramp down to
/// rest) over vp, each run of consecutive members as the interval [min T, max T] of
/// their durations (inner approximations of the true images), plus "stop, then a
/// rest-to-rest move" from its floor on. Returns (intervals, floor).
fn reachable_by_scan(v0: f64, a0: f64, d: f64, lim: &Limits1) -> (Vec<(f64, f64)>, f64) {
    let pb = from_state::brake_point(v0, a0, lim);
    let (v, a, d, pb) = if d >= pb {
        (v0, a0, d, pb)
    } else {
        (-v0, -a0, -d, -pb)
    };
    let stop = ramp(v, a, 0.0, lim).duration();
    let floor = stop + rest_to_rest::time_optimal_duration(d - pb, lim);
    let n = 20_000;
    let mut runs: Vec<(f64, f64)> = Vec::new();
    let mut in_run = false;
    for k in 1..=n {
        let vp = lim.v * k as f64 / n as f64;
        let r1 = ramp(v, a, vp, lim);
        let end = r1.integrate(Kin { p: 0.0, v, a });
        let (t1, t2, d2) = ramp_from_rest(vp, lim);
        let dist = end.p + d2;
        if dist > d {
            in_run = false;
            continue;
        }
        let t = r1.duration() + 2.0 * t1 + t2 + (d - dist) / vp;
        match runs.last_mut() {
            Some(run) if in_run => *run = (run.0.min(t), run.1.max(t)),
            _ => runs.push((t, t)),
        }
        in_run = true;
    }
    (runs, floor)
}

prop_compose! {
    /// A joint decelerating towards a target just past its brake point (where the
    /// stretch family has blocked intervals), and a requested duration above its minimum.
    fn decelerating_problem()(v in 0.2f64..5.0, a in 0.2f64..5.0, j in 0.2f64..20.0,
                              fa in 0.05f64..1.0, fv in 0.0f64..1.0, u in 0.0f64..1.0,
                              x in 0.0f64..1.0, neg in prop::bool::ANY)
                              -> (Limits1, f64, f64, f64, f64) {
        let lim = Limits1 { v, a, j };
        let a0 = -fa * a.min(0.99 * (4.0 * j * v).sqrt());
        // Stop velocity v0 − a0²/(2j) within ±vmax, v0 ≥ 0.
        let lo = (-v + a0 * a0 / (2.0 * j)).max(0.0);
        let v0 = lo + fv * (v - lo) * 0.999;
        let d = from_state::brake_point(v0, a0, &lim) + 2.0 * u * u * u;
        let sg = if neg { -1.0 } else { 1.0 };
        (lim, sg * v0, sg * a0, sg * d, x)
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, max_global_rejects: 100_000, ..ProptestConfig::default() })]

    #[test]
    fn soft_single_joint_exact_continuous_within_limits((l, s, q1) in joint_problem()) {
        let lim = limits(&[l[0]], &[l[1]], &[l[2]], 1e3);
        let tr = Trajectory::plan(&soft_request(&[s[0]], &[s[1]], &[s[2]], &[q1], lim)).expect("plans");
        prop_assert!(!tr.braked());
        let start = tr.sample(0.0);
        prop_assert_eq!((start.q[0], start.qd[0], start.qdd[0]), (s[0], s[1], s[2]));
        let end = tr.sample(tr.duration());
        prop_assert_eq!((end.q[0], end.qd[0], end.qdd[0]), (q1, 0.0, 0.0));
        // The last piece lands on the target itself, not only the held final state.
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        prop_assert!((near.q[0] - q1).abs() < 1e-9 && near.qd[0].abs() < 1e-9);
        tr.check_limits(&lim, true).map_err(|e| TestCaseError::fail(e.to_string()))?;
        check_walk(&tr, 1, &[l], true, 0.0)?;
    }

    /// Pontryagin structure of a time-optimal profile: at every instant one
    /// constraint is saturated (|jerk| = jmax, or |a| = amax, or |v| = vmax with a = 0).
    /// A slower profile (e.g. a stretched one) always has an unsaturated stretch.
    #[test]
    fn soft_motion_is_bang_bang((l, s, q1) in joint_problem(), u in 0.0f64..1.0) {
        prop_assume!((q1 - s[0]).abs() > 1e-3 || s[1].abs() > 1e-3);
        let lim = limits(&[l[0]], &[l[1]], &[l[2]], 1e3);
        let tr = Trajectory::plan(&soft_request(&[s[0]], &[s[1]], &[s[2]], &[q1], lim)).expect("plans");
        let x = tr.sample(u * tr.duration());
        let sat = (x.jerk[0].abs() - l[2]).abs() < 1e-9 * l[2]
            || (x.qdd[0].abs() - l[1]).abs() < 1e-7 * l[1]
            || (x.qd[0].abs() - l[0]).abs() < 1e-7 * l[0];
        prop_assert!(sat, "nothing saturated at t = {}: {:?}", u * tr.duration(), x);
    }

    /// Minimality against an independent method: from rest, the seed's closed form
    /// and the from-state root search must agree; and no target can be reached
    /// faster by overshooting it (a bisection over targets).
    #[test]
    fn soft_motion_minimal_against_independent_search(l in (0.2f64..5.0, 0.2f64..5.0, 0.2f64..20.0), d in 1e-3f64..10.0) {
        let lim = Limits1 { v: l.0, a: l.1, j: l.2 };
        let closed = rest_to_rest::time_optimal(d, &lim).duration();
        let search = from_state::time_optimal(1e-300, 0.0, d, &lim).duration();
        prop_assert!((closed - search).abs() <= 1e-9 * closed, "{closed} vs {search}");
        // Time grows with distance: a shorter motion to d would imply one to d' < d.
        let shorter = rest_to_rest::time_optimal(d * 0.999, &lim).duration();
        prop_assert!(shorter < closed);
    }

    #[test]
    fn soft_from_state_not_beaten_by_brute_force((l, s, q1) in joint_problem()) {
        // Brute force over a second family (ramp to a peak velocity vp, cruise, stop;
        // 16-point grid plus root search, and "stop, then move"): asked for any duration
        // below the optimum it finds nothing; at and above it, it lands on q1 exactly on
        // time (or reports a blocked duration below its guaranteed floor).
        let lim1 = Limits1 { v: l[0], a: l[1], j: l[2] };
        let lim = limits(&[l[0]], &[l[1]], &[l[2]], 1e3);
        let tr = Trajectory::plan(&soft_request(&[s[0]], &[s[1]], &[s[2]], &[q1], lim)).expect("plans");
        let d = q1 - s[0];
        let st = Stretch::new(s[1], s[2], d, &lim1);
        let k0 = Kin { p: 0.0, v: s[1], a: s[2] };
        for k in 1..=20 {
            let t = tr.duration() * (1.0 - 0.01 * k as f64);
            prop_assert!(st.phases(t, &lim1).is_none(), "a motion of {t} s beats the optimum {}", tr.duration());
        }
        for k in 0..=100 {
            let t = tr.duration() * (1.0 + k as f64 * 0.02);
            match st.phases(t, &lim1) {
                Some(ph) => {
                    let end = ph.integrate(k0);
                    prop_assert!((end.p - d).abs() < 1e-6 * (1.0 + d.abs()), "stretch to {t} misses: {} vs {d}", end.p);
                    prop_assert!((ph.duration() - t).abs() < 1e-9 * t);
                }
                None => prop_assert!(t < st.guaranteed(), "{t} s should be reachable"),
            }
        }
    }

    #[test]
    fn soft_stretched_finishes_exactly_at_t((l, s, q1) in joint_problem(), extra in 0.0f64..20.0) {
        let lim = limits(&[l[0]], &[l[1]], &[l[2]], 1e3);
        let mut req = soft_request(&[s[0]], &[s[1]], &[s[2]], &[q1], lim);
        let tmin = Trajectory::plan(&req).expect("plans").duration();
        req.profile = Profile::Soft { min_duration: Some(tmin + extra) };
        let tr = Trajectory::plan(&req).expect("plans");
        prop_assert!(tr.duration() >= tmin + extra - 1e-12);
        let lim1 = Limits1 { v: l[0], a: l[1], j: l[2] };
        if Stretch::new(s[1], s[2], q1 - s[0], &lim1).phases(tmin + extra, &lim1).is_some() {
            prop_assert!((tr.duration() - (tmin + extra)).abs() < 1e-9 * (1.0 + tmin + extra));
        }
        tr.check_limits(&lim, true).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        prop_assert!((near.q[0] - q1).abs() < 1e-8 && near.qd[0].abs() < 1e-8);
        check_walk(&tr, 1, &[l], true, 0.0)?;
    }

    /// Synchronisation takes the smallest duration the joint reaches: asked for T
    /// (above its minimum), the plan takes T itself when the family (or "stop, then
    /// move") has a member of that duration, and otherwise the end of the blocked
    /// interval — no duration between T and the planned one is reachable (scan oracle).
    #[test]
    fn soft_synchronised_duration_is_the_smallest_reachable((lim1, v0, a0, d, x) in decelerating_problem()) {
        let lim = limits(&[lim1.v], &[lim1.a], &[lim1.j], 1e3);
        let mut req = soft_request(&[0.0], &[v0], &[a0], &[d], lim);
        let t_opt = Trajectory::plan(&req).expect("plans").duration();
        let t_req = t_opt * (1.0 + 1e-6 + x);
        req.profile = Profile::Soft { min_duration: Some(t_req) };
        let tr = Trajectory::plan(&req).expect("plans");
        let t = tr.duration();
        prop_assert!(t >= t_req * (1.0 - 1e-12));
        let near = tr.sample(t * (1.0 - 1e-12));
        prop_assert!((near.q[0] - d).abs() < 1e-8 && near.qd[0].abs() < 1e-8);
        tr.check_limits(&lim, true).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let (runs, floor) = reachable_by_scan(v0, a0, d, &lim1);
        let reachable = |s: f64| s >= floor || runs.iter().any(|&(lo, hi)| s >= lo && s <= hi);
        if t > t_req * (1.0 + 1e-9) {
            for k in 0..=20 {
                let s = t_req + (t - t_req) * k as f64 / 20.0;
                let s = s.min(t * (1.0 - 1e-6));
                prop_assert!(!reachable(s), "asked {t_req}, planned {t}, yet {s} is reachable (runs {runs:?}, floor {floor})");
            }
        }
    }

    #[test]
    fn soft_synchronised_joints_finish_together(ps in prop::collection::vec(joint_problem(), 1..=8)) {
        let dof = ps.len();
        let col = |f: &dyn Fn(&Problem) -> f64| ps.iter().map(f).collect::<Vec<_>>();
        let lim = limits(&col(&|p| p.0[0]), &col(&|p| p.0[1]), &col(&|p| p.0[2]), 1e3);
        let req = soft_request(&col(&|p| p.1[0]), &col(&|p| p.1[1]), &col(&|p| p.1[2]), &col(&|p| p.2), lim);
        let tr = Trajectory::plan(&req).expect("plans");
        let mut slowest = 0.0f64;
        for i in 0..dof {
            let one = soft_request(&[ps[i].1[0]], &[ps[i].1[1]], &[ps[i].1[2]], &[ps[i].2], limits(&[ps[i].0[0]], &[ps[i].0[1]], &[ps[i].0[2]], 1e3));
            slowest = slowest.max(Trajectory::plan(&one).expect("plans").duration());
        }
        prop_assert!(tr.duration() >= slowest * (1.0 - 1e-12));
        tr.check_limits(&lim, true).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        for i in 0..dof {
            prop_assert!((near.q[i] - ps[i].2).abs() < 1e-8, "joint {i} not there at the end");
            prop_assert!(near.qd[i].abs() < 1e-8);
        }
        let ls: Vec<[f64; 3]> = ps.iter().map(|p| p.0).collect();
        check_walk(&tr, dof, &ls, true, 0.0)?;
    }

    /// Braking: from a state bound to cross vmax the motion first brakes, |v| never
    /// exceeds the unavoidable v0 + a0|a0|/(2 jmax), and all limits hold after it.
    #[test]
    fn soft_brakes_when_vmax_would_be_crossed(v in 0.2f64..3.0, a in 0.2f64..3.0, j in 0.2f64..10.0,
                                             fv in 0.5f64..1.0, fa in 0.2f64..1.0, q1 in -3.0f64..3.0, sign in prop::bool::ANY) {
        let sg = if sign { 1.0 } else { -1.0 };
        let (v0, a0) = (sg * fv * v, sg * fa * a);
        let s0 = stop_velocity(v0, a0, j);
        prop_assume!(s0.abs() > v * (1.0 + 1e-6));
        let lim = limits(&[v], &[a], &[j], 1e3);
        let tr = Trajectory::plan(&soft_request(&[0.0], &[v0], &[a0], &[q1], lim)).expect("plans");
        prop_assert!(tr.braked());
        let n = 4000;
        let xs: Vec<_> = (0..=n).map(|k| tr.sample(tr.duration() * k as f64 / n as f64)).collect();
        let peak = (0..=n).max_by(|&i, &k| xs[i].qd[0].abs().total_cmp(&xs[k].qd[0].abs())).unwrap_or(0);
        let mut back = false;
        for x in &xs[peak..] {
            prop_assert!(x.qd[0].abs() <= s0.abs() * (1.0 + 1e-9));
            prop_assert!(x.qdd[0].abs() <= a * (1.0 + 1e-9));
            // Past the velocity peak |v| only falls back under vmax and stays there.
            if x.qd[0].abs() <= v * (1.0 + 1e-9) { back = true; }
            if back { prop_assert!(x.qd[0].abs() <= v * (1.0 + 1e-9), "back over vmax"); }
        }
        prop_assert!(xs[peak].qd[0].abs() <= s0.abs() * (1.0 + 1e-9));
        let end = tr.sample(tr.duration());
        prop_assert_eq!((end.q[0], end.qd[0]), (q1, 0.0));
        // The last piece lands on the target itself (no jump onto the final state).
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        prop_assert!((near.q[0] - q1).abs() < 1e-7, "{} vs {q1} just before the end", near.q[0]);
    }

    #[test]
    fn stop_reaches_rest_within_limits((l, s, _q1) in joint_problem()) {
        let lim = limits(&[l[0]], &[l[1]], &[l[2]], 1e3);
        let st = MotionState { q: jv(&[s[0]]), qd: jv(&[s[1]]), qdd: jv(&[s[2]]) };
        let tr = stop_trajectory(1, &st, &lim).expect("stops");
        let end = tr.sample(tr.duration());
        prop_assert_eq!((end.qd[0], end.qdd[0]), (0.0, 0.0));
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        prop_assert!(near.qd[0].abs() < 1e-9);
        // Stopping is never slower than the time-optimal soft motion to the stop point.
        let again = Trajectory::plan(&soft_request(&[s[0]], &[s[1]], &[s[2]], &[end.q[0]], lim)).expect("plans");
        prop_assert!(tr.duration() <= again.duration() + 1e-9 * (1.0 + tr.duration()));
        check_walk(&tr, 1, &[l], true, 0.0)?;
    }

    #[test]
    fn polynomials_hit_boundaries_exactly(q0 in -3.0f64..3.0, q1 in -3.0f64..3.0, v0 in -1.0f64..1.0, v1 in -1.0f64..1.0,
                                          a0 in -1.0f64..1.0, a1 in -1.0f64..1.0, t in 0.1f64..10.0) {
        let lim = limits(&[10.0], &[10.0], &[10.0], 1e3);
        for quintic in [false, true] {
            let req = MotionRequest {
                dof: 1,
                start: MotionState { q: jv(&[q0]), qd: jv(&[v0]), qdd: jv(&[a0]) },
                target: MotionState { q: jv(&[q1]), qd: jv(&[v1]), qdd: jv(&[a1]) },
                profile: if quintic { Profile::Quintic { duration: t } } else { Profile::Cubic { duration: t } },
                limits: lim,
            };
            let tr = Trajectory::plan(&req).expect("plans");
            let (s, e) = (tr.sample(0.0), tr.sample(t * (1.0 - 1e-13)));
            prop_assert!((s.q[0] - q0).abs() < 1e-12 && (s.qd[0] - v0).abs() < 1e-12);
            prop_assert!((e.q[0] - q1).abs() < 1e-9 && (e.qd[0] - v1).abs() < 1e-9);
            if quintic {
                prop_assert!((s.qdd[0] - a0).abs() < 1e-12 && (e.qdd[0] - a1).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn lspb_is_continuous_and_exact(q0 in -3.0f64..3.0, q1 in -3.0f64..3.0, t in 0.1f64..10.0, f in 1.0001f64..2.0) {
        let h = q1 - q0;
        prop_assume!(h.abs() > 1e-6);
        let lim = limits(&[1e3], &[1e4], &[1.0], 1e3);
        let v = f * h / t;
        let req = MotionRequest {
            dof: 1,
            start: MotionState::at_rest(jv(&[q0])),
            target: MotionState::at_rest(jv(&[q1])),
            profile: Profile::Lspb { duration: t, cruise_velocity: Some(jv(&[v])) },
            limits: lim,
        };
        let tr = Trajectory::plan(&req).expect("plans");
        // The blend acceleration: large when the cruise velocity is barely above the mean.
        let acc = v.abs() / (t - h / v);
        let end = tr.sample(t);
        prop_assert!((end.q[0] - q1).abs() < 1e-9 && end.qd[0].abs() < 1e-9);
        // Just before the end the velocity is acc·dt (decelerating to rest), no more.
        let dt = t * 1e-13;
        let e = tr.sample(t - dt);
        prop_assert!((e.q[0] - q1).abs() < 1e-9 && e.qd[0].abs() <= 2.0 * acc * dt + 1e-12);
        let peaks = tr.peaks();
        prop_assert!((peaks.velocity[0] - v.abs()).abs() < 1e-9 * v.abs());
        check_walk(&tr, 1, &[[v.abs(), acc, f64::INFINITY]], false, 0.0)?;
    }
}

/// A brake leaves v > vmax with a < 0 and the stop velocity at vmax; a target between
/// the brake point and the end of "level off at vmax, then stop" used to be planned as
/// a plain stop past it, jumping onto the target at the end (found by a 200 000-case
/// stress run: 39 such joints, and 380 plans refused for overrunning ±1000 rad).
#[test]
fn braked_motion_to_a_target_short_of_the_vmax_level_off_lands_on_it() {
    let lim = limits(
        &[2.1901517096628678],
        &[4.50388023461479],
        &[5.215604937990103],
        1e3,
    );
    let (q0, v0, a0, q1) = (
        -2.832663065155587,
        0.9618563889013362,
        4.36709208546959,
        1.0732055490822427,
    );
    let tr = Trajectory::plan(&soft_request(&[q0], &[v0], &[a0], &[q1], lim)).expect("plans");
    assert!(tr.braked());
    let near = tr.sample(tr.duration() * (1.0 - 1e-12));
    assert!((near.q[0] - q1).abs() < 1e-8, "{} vs {q1}", near.q[0]);
    // |v| may exceed vmax during the brake, up to the unavoidable v0 + a0²/(2 jmax).
    let v_peak = stop_velocity(v0, a0, lim.jerk[0]);
    check_walk(
        &tr,
        1,
        &[[v_peak, lim.acceleration[0], lim.jerk[0]]],
        true,
        0.0,
    )
    .expect("continuous, |v| within the brake's peak, a and jerk within the limits");
    let later = tr.sample(0.6 * tr.duration());
    assert!(later.qd[0].abs() <= lim.velocity[0] * (1.0 + 1e-9));
}

/// A joint decelerating towards a target just past its brake point, asked for
/// durations just above its minimum (found by `soft_synchronised_duration_is_the_smallest_reachable`).
/// The stretch family cannot take them (a blocked interval: until 2026-12-02 they were
/// raised to its end); profiles whose acceleration does not return to zero between
/// the halves (`soft::free`) can, and Ruckig 0.19.4 with `minimum_duration` finishes
/// at exactly these durations (1 + 1e-6, 1.001, 1.01, 1.05 × its 4.19433754433952 s).
#[test]
fn durations_the_stretch_family_cannot_take_are_reached_as_ruckig_reaches_them() {
    let lim1 = Limits1 {
        v: 1.607882619036064,
        a: 1.872704276179884,
        j: 0.2,
    };
    let (v0, a0, d) = (0.9419946165717734, -0.05614064044731314, 1.908092858450313);
    let lim = limits(&[lim1.v], &[lim1.a], &[lim1.j], 1e3);
    let mut req = soft_request(&[0.0], &[v0], &[a0], &[d], lim);
    let t_opt = Trajectory::plan(&req).expect("plans").duration();
    assert!((t_opt - 4.19433754433952).abs() < 1e-9 * t_opt, "{t_opt}");
    let (runs, _floor) = reachable_by_scan(v0, a0, d, &lim1);
    for f in [1.0 + 1e-6, 1.001, 1.01, 1.05] {
        let t_req = t_opt * f;
        // The stretch family's scan has no member within 1e-6 of it.
        assert!(
            !runs
                .iter()
                .any(|r| r.0 <= t_req * (1.0 + 1e-6) && t_req <= r.1 * (1.0 + 1e-6)),
            "{t_req} s is in the stretch family after all"
        );
        req.profile = Profile::Soft {
            min_duration: Some(t_req),
        };
        let tr = Trajectory::plan(&req).expect("plans");
        assert!(
            (tr.duration() - t_req).abs() < 1e-12 * t_req,
            "{} vs {t_req}",
            tr.duration()
        );
        let end = tr.sample(tr.duration());
        assert_eq!((end.q[0], end.qd[0], end.qdd[0]), (d, 0.0, 0.0));
        let near = tr.sample(tr.duration() * (1.0 - 1e-12));
        assert!((near.q[0] - d).abs() < 1e-9 && near.qd[0].abs() < 1e-9);
        tr.check_limits(&lim, true).expect("within the limits");
        check_walk(&tr, 1, &[[lim1.v, lim1.a, lim1.j]], true, 0.0)
            .expect("continuous, within the limits");
    }
}
