//! Seed Table 4 against the reference file: time-optimal durations, phases and
//! samples of soft motion; tf = 5 s cubic and quintic coefficients and samples.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;
use microrobot_trajectory::polynomial::{cubic_coefficients, quintic_coefficients};
use microrobot_trajectory::soft::{Limits1, rest_to_rest};
use microrobot_trajectory::{MotionRequest, MotionState, Profile, Trajectory};

fn joints() -> Vec<serde_json::Value> {
    load("trajectory_reference.json")["joints"]
        .as_array()
        .expect("joints")
        .clone()
}

fn single(j: &serde_json::Value) -> MotionRequest {
    let lim = limits(
        &[f(&j["vmax_radps"])],
        &[f(&j["amax_radps2"])],
        &[f(&j["jmax_radps3"])],
        4.0,
    );
    soft_request(
        &[f(&j["theta_i_rad"])],
        &[0.0],
        &[0.0],
        &[f(&j["theta_f_rad"])],
        lim,
    )
}

#[test]
fn soft_motion_durations_match_table4() {
    for j in joints() {
        let tr = Trajectory::plan(&single(&j)).expect("plans");
        assert_close(tr.duration(), f(&j["ruckig_duration_s"]), 1e-12, "duration");
        assert_close(
            tr.duration(),
            f(&j["soft_motion_closed_form"]["duration_s"]),
            1e-12,
            "closed form",
        );
    }
}

#[test]
fn soft_motion_phases_match_table4() {
    for j in joints() {
        let lim = Limits1 {
            v: f(&j["vmax_radps"]),
            a: f(&j["amax_radps2"]),
            j: f(&j["jmax_radps3"]),
        };
        let ph = rest_to_rest::time_optimal(f(&j["distance_rad"]), &lim);
        let got: Vec<f64> = ph.p[..ph.n].iter().map(|p| p.t).collect();
        let want: Vec<f64> = fs(&j["ruckig_phase_durations_s"])
            .into_iter()
            .filter(|&t| t > 0.0)
            .collect();
        assert_eq!(got.len(), want.len(), "phase count");
        for (g, w) in got.iter().zip(&want) {
            assert_close(*g, *w, 1e-9, "phase");
        }
        let (case, d1, d2) = rest_to_rest::seed_case(f(&j["distance_rad"]), &lim);
        let cf = &j["soft_motion_closed_form"];
        assert_eq!(case as u64, cf["case"].as_u64().expect("case"));
        assert_close(d1, f(&cf["Dthr1_rad"]), 1e-12, "Dthr1");
        assert_close(d2, f(&cf["Dthr2_rad"]), 1e-12, "Dthr2");
    }
}

#[test]
fn soft_motion_samples_match_table4() {
    for j in joints() {
        let tr = Trajectory::plan(&single(&j)).expect("plans");
        let s = &j["samples"];
        let (t, q, v, a) = (
            fs(&s["t_s"]),
            fs(&s["position_rad"]),
            fs(&s["velocity_radps"]),
            fs(&s["acceleration_radps2"]),
        );
        for k in 0..t.len() {
            let x = tr.sample(t[k]);
            assert!(
                (x.q[0] - q[k]).abs() < 1e-9,
                "q at {}: {} vs {}",
                t[k],
                x.q[0],
                q[k]
            );
            assert!((x.qd[0] - v[k]).abs() < 1e-9, "qd at {}", t[k]);
            assert!((x.qdd[0] - a[k]).abs() < 1e-9, "qdd at {}", t[k]);
        }
    }
}

#[test]
fn table4_synchronised_takes_the_slowest_joint() {
    let js = joints();
    let col = |k: &str| js.iter().map(|j| f(&j[k])).collect::<Vec<_>>();
    let lim = limits(
        &col("vmax_radps"),
        &col("amax_radps2"),
        &col("jmax_radps3"),
        4.0,
    );
    let req = soft_request(
        &col("theta_i_rad"),
        &[0.0; 6],
        &[0.0; 6],
        &col("theta_f_rad"),
        lim,
    );
    let tr = Trajectory::plan(&req).expect("plans");
    let reference = &load("trajectory_reference.json")["synchronized_6dof"];
    assert_close(
        tr.duration(),
        f(&reference["ruckig_duration_s"]),
        1e-12,
        "sync duration",
    );
    tr.check_limits(&lim, true).expect("within limits");
    let end = tr.sample(tr.duration());
    for i in 0..6 {
        assert_close(end.q[i], col("theta_f_rad")[i], 1e-12, "end");
        assert_eq!(end.qd[i], 0.0);
    }
}

#[test]
fn cubic_and_quintic_tf5_match_table4() {
    for j in joints() {
        let p = &j["polynomials_tf5"];
        let (q0, q1, tf) = (f(&j["theta_i_rad"]), f(&j["theta_f_rad"]), f(&p["tf_s"]));
        let c = cubic_coefficients(q0, q1, 0.0, 0.0, tf);
        for (g, w) in c.iter().zip(fs(&p["cubic_coeffs_rad"])) {
            assert_close(*g, w, 1e-12, "cubic coefficient");
        }
        let a = 5f64.to_radians();
        let c = quintic_coefficients(q0, q1, 0.0, 0.0, a, -a, tf);
        for (g, w) in c.iter().zip(fs(&p["quintic_coeffs_rad"])) {
            assert_close(*g, w, 1e-12, "quintic coefficient");
        }
        let lim = limits(&[10.0], &[10.0], &[10.0], 4.0);
        let mk = |profile, a0: f64, a1: f64| MotionRequest {
            dof: 1,
            start: MotionState {
                qdd: jv(&[a0]),
                ..MotionState::at_rest(jv(&[q0]))
            },
            target: MotionState {
                qdd: jv(&[a1]),
                ..MotionState::at_rest(jv(&[q1]))
            },
            profile,
            limits: lim,
        };
        let cub = Trajectory::plan(&mk(Profile::Cubic { duration: tf }, 0.0, 0.0)).expect("cubic");
        let qui = Trajectory::plan(&mk(Profile::Quintic { duration: tf }, a, -a)).expect("quintic");
        for ((t, qc), qq) in fs(&p["t_s"])
            .into_iter()
            .zip(fs(&p["cubic_position_rad"]))
            .zip(fs(&p["quintic_position_rad"]))
        {
            assert!((cub.sample(t).q[0] - qc).abs() < 1e-9, "cubic at {t}");
            assert!((qui.sample(t).q[0] - qq).abs() < 1e-9, "quintic at {t}");
        }
    }
}

#[test]
fn cubic_at_tf5_needs_more_than_amax() {
    // Seed: the tf = 5 s cubic needs 86.4 deg/s² where joints 1, 4, 6 allow 80
    // (and 43.2 where joints 2, 3, 5 allow 40).
    for j in joints() {
        let lim = limits(
            &[f(&j["vmax_radps"])],
            &[f(&j["amax_radps2"])],
            &[f(&j["jmax_radps3"])],
            4.0,
        );
        let req = MotionRequest {
            profile: Profile::Cubic { duration: 5.0 },
            ..soft_request(
                &[f(&j["theta_i_rad"])],
                &[0.0],
                &[0.0],
                &[f(&j["theta_f_rad"])],
                lim,
            )
        };
        let tr = Trajectory::plan(&req).expect("plans");
        let peak = tr.peaks().acceleration[0].to_degrees();
        let want = 6.0 * f(&j["distance_deg"]) / 25.0;
        assert_close(peak, want, 1e-9, "cubic peak acceleration");
        let err = tr.check_limits(&lim, false).expect_err("amax exceeded");
        assert!(err.to_string().contains("limits.acceleration"), "{err}");
        let fast = Trajectory::plan(&MotionRequest {
            profile: Profile::Cubic { duration: 6.0 },
            ..req
        })
        .expect("plans");
        let fits = fast.peaks().acceleration[0] <= f(&j["amax_radps2"]);
        assert_eq!(fast.check_limits(&lim, false).is_ok(), fits);
    }
}
