//! Commanding a running pipeline: a move arriving mid-motion replans without a jump,
//! `send` reports the planner's verdict on its own command (also with senders in
//! parallel), `top` shows every service.

use std::time::Duration;

use crate::common::*;

/// Table 4's limits of the seed arm (deg/s², deg/s³), per joint.
const ACC_DEG_S2: [f64; 6] = [80.0, 40.0, 40.0, 80.0, 40.0, 80.0];
const JERK_DEG_S3: [f64; 6] = [160.0, 80.0, 80.0, 160.0, 80.0, 160.0];

#[test]
fn a_move_arriving_mid_motion_replans_without_a_jump() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("replan");
    let cfg = write_config(dir.path(), &inst, "", "");
    let cfg_s = cfg.to_str().expect("utf-8").to_string();
    let rec = Recorder::start(&inst);
    let proc = start(&[
        "run",
        "--config",
        &cfg_s,
        "--no-program",
        "--duration",
        "120",
    ]);
    wait_ready(&inst, 60.0);

    let send = |args: &[&str]| {
        let mut all = vec!["send", "--instance", &inst, "--config", &cfg_s];
        all.extend_from_slice(args);
        run(&all, 60.0)
    };
    // Stretched to 6 s, so the second move arrives mid-motion even when a loaded machine
    // delays it by seconds.
    let first = send(&[
        "move",
        "--deg",
        "--joints",
        "30,30,30,30,30,30",
        "--duration",
        "6",
    ]);
    assert_eq!(first.code(), Some(0), "first move: {}", first.stderr);
    std::thread::sleep(Duration::from_millis(800));
    let second = send(&["move", "--deg", "--joints", "10,10,10,10,10,10"]);
    assert_eq!(second.code(), Some(0), "second move: {}", second.stderr);

    // `top` sees all three services while they run.
    let top = run(&["top", "--instance", &inst, "--once", "--json"], 60.0);
    assert_eq!(top.code(), Some(0), "top: {}", top.stderr);
    let table: serde_json::Value = serde_json::from_str(top.stdout.trim()).expect("top JSON");
    let services = table["services"].as_array().expect("services");
    assert_eq!(services.len(), 3, "{table}");
    // And the latency budget by hop: the three hops inside the end-to-end latency have
    // counted the pipeline's messages, and their exact means add up to its mean (each
    // service counts since its own start; top reads the statuses a few ms apart, so the
    // sums agree to within a few samples' worth, not exactly).
    let hops = &table["latency_by_hop"];
    let mean = |h: &serde_json::Value| h["mean"].as_f64().expect("mean");
    let inner = [
        "setpoint_to_dynamics_us",
        "dynamics_compute_us",
        "torque_to_actuator_us",
    ];
    for h in inner {
        assert!(
            hops["hops"][h]["count"].as_u64().expect("count") > 100,
            "{h}: {hops}"
        );
    }
    let sum: f64 = inner.iter().map(|h| mean(&hops["hops"][*h])).sum();
    let e2e = mean(&hops["end_to_end_us"]);
    assert!(
        e2e > 0.0 && (sum - e2e).abs() < 0.25 * e2e,
        "hop means {sum} vs end-to-end {e2e}: {hops}"
    );

    // An unreachable pose is refused by the planner, and `send` says so.
    let refused = send(&["move", "--pose", "10,10,10,1,0,0,0"]);
    assert_ne!(refused.code(), Some(0), "unreachable pose must be refused");
    assert!(refused.stderr.contains("refused"), "{}", refused.stderr);

    std::thread::sleep(Duration::from_secs(6));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let sp = rec.finish().setpoints;
    assert!(sp.len() > 1000, "setpoints recorded: {}", sp.len());

    let dt = 1e-3;
    let mut moving_seen = false;
    for w in sp.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let ticks = b.header.tick.saturating_sub(a.header.tick);
        assert!(
            ticks >= 1,
            "ticks increase: {} -> {}",
            a.header.tick,
            b.header.tick
        );
        let h = ticks as f64 * dt;
        for j in 0..6 {
            let (amax, jmax) = (ACC_DEG_S2[j].to_radians(), JERK_DEG_S3[j].to_radians());
            let at = || format!("joint {} at tick {}", j + 1, b.header.tick);
            let dq = b.q[j] - a.q[j] - 0.5 * (a.qd[j] + b.qd[j]) * h;
            assert!(
                dq.abs() <= amax * h * h + 1e-9,
                "position jump {dq:e} rad, {}",
                at()
            );
            let dqd = b.qd[j] - a.qd[j];
            assert!(
                dqd.abs() <= amax * h * 1.01 + 1e-9,
                "velocity jump {dqd:e} rad/s, {}",
                at()
            );
            let dqdd = b.qdd[j] - a.qdd[j];
            assert!(
                dqdd.abs() <= jmax * h * 1.01 + 1e-9,
                "acceleration jump {dqdd:e} rad/s², {}",
                at()
            );
            moving_seen |= a.qd[j].abs() > 0.1;
        }
    }
    assert!(moving_seen, "the arm moved");
    // Replanned mid-motion: the first target was never reached, the second was.
    let top_q = sp.iter().map(|s| s.q[0]).fold(f64::MIN, f64::max);
    assert!(
        top_q < 29f64.to_radians(),
        "joint 1 turned back before 30 deg: max {top_q} rad"
    );
    let last = sp.last().expect("setpoints");
    for j in 0..6 {
        assert!(
            (last.q[j] - 10f64.to_radians()).abs() < 1e-6 && last.qd[j].abs() < 1e-9,
            "joint {} ends at rest at 10 deg: q {} qd {}",
            j + 1,
            last.q[j],
            last.qd[j]
        );
    }
}

/// Eight `microrobot send` at once, four stops (accepted) and four moves to an
/// unreachable pose (refused), three rounds: each sender reports the planner's verdict
/// on its own command, not whichever counter moved first.
#[test]
fn parallel_sends_each_get_their_own_verdict() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("parallel-send");
    let cfg = write_config(dir.path(), &inst, "", "");
    let proc = start_holding(&inst, &cfg, 300, None);
    let mut wrong = Vec::new();
    for round in 0..3 {
        let senders: Vec<_> = (0..8)
            .map(|k| {
                let (inst, cfg) = (inst.clone(), cfg.clone());
                std::thread::spawn(move || {
                    let stop = k % 2 == 0;
                    let args: &[&str] = if stop {
                        &["stop"]
                    } else {
                        &["move", "--pose", "10,10,10,1,0,0,0"]
                    };
                    (stop, send(&inst, &cfg, args))
                })
            })
            .collect();
        for h in senders {
            let (stop, out) = h.join().expect("sender thread");
            let ok = if stop {
                out.code() == Some(0) && out.stdout.contains("accepted")
            } else {
                out.code() != Some(0) && out.stderr.contains("unreachable")
            };
            if !ok {
                wrong.push(format!(
                    "round {round}, {}: exit {:?}, stdout {:?}, stderr {:?}",
                    if stop { "stop" } else { "unreachable move" },
                    out.code(),
                    out.stdout.trim(),
                    out.stderr.trim()
                ));
            }
        }
    }
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    assert!(
        wrong.is_empty(),
        "{} of 24 senders reported a verdict not on their own command:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}
