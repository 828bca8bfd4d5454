//! The latency budget by hop in a run's summary: every hop is present with as many
//! samples as there were messages of its kind, and the three hops inside the end-to-end
//! latency add up to it exactly, checked in ns against the stamps of every torque on the
//! bus and the services' final statuses. Latencies themselves are never held to a
//! wall-clock figure (the machine is shared); only structure, counts and sums.

mod common;

use common::*;
use microrobot_messages::{ServiceRole, ServiceStatus, TorqueCommand, state_flags};

/// The hop keys of the summary's `hops` object, in chain order.
const HOPS: [&str; 5] = [
    "planner_wake_to_setpoint_us",
    "setpoint_to_dynamics_us",
    "dynamics_compute_us",
    "torque_to_actuator_us",
    "actuator_step_to_state_us",
];

/// Setpoint stamp → torque stamp of `t`, in ns.
fn setpoint_to_torque_ns(t: &TorqueCommand) -> u64 {
    assert!(
        t.header.stamp_ns >= t.header.source_stamp_ns && t.header.source_stamp_ns > 0,
        "torque {} stamped before its setpoint: {:?}",
        t.header.seq,
        t.header
    );
    t.header.stamp_ns - t.header.source_stamp_ns
}

/// The last status `role` published (its final one after a clean stop).
fn last_status(statuses: &[ServiceStatus], role: ServiceRole) -> ServiceStatus {
    *statuses
        .iter()
        .rev()
        .find(|s| s.role == role as u32)
        .unwrap_or_else(|| panic!("no status of the {}", role.name()))
}

#[test]
fn a_run_summary_splits_the_end_to_end_latency_into_hops_that_add_up() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("hops");
    let cfg = write_config(dir.path(), &inst, "", "");
    let summary_path = dir.path().join("summary.json");
    // Free-running at 1 kHz: a sleeping poller keeps up with every stream.
    let rec = Recorder::start(&inst);
    let out = run(
        &[
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--no-program",
            "--duration",
            "2",
            "--quiet",
            "--summary-json",
            summary_path.to_str().expect("utf-8"),
        ],
        120.0,
    );
    let streams = rec.finish();
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let s = summary(&summary_path);
    // Every torque the actuator saw it took (what it refused or lost would be neither
    // taken nor in flight).
    assert_eq!(s["lost_messages"], 0, "{s}");
    assert_eq!(s["refused_messages"], 0, "{s}");

    // The printed summary has the table.
    for row in [
        "latency by hop (µs)",
        "planner wake → setpoint sent",
        "+ setpoint → dynamics awake",
        "+ dynamics compute → torque",
        "+ torque → actuator received",
        "= end-to-end",
        "actuator step → state sent",
    ] {
        assert!(out.stdout.contains(row), "`{row}` missing:\n{}", out.stdout);
    }

    // Every hop, with every figure.
    let hops = &s["hops"];
    let figure = |hop: &str, key: &str| {
        hops[hop][key]
            .as_f64()
            .unwrap_or_else(|| panic!("hops.{hop}.{key} missing: {s}"))
    };
    let count = |hop: &str| {
        hops[hop]["count"]
            .as_u64()
            .unwrap_or_else(|| panic!("hops.{hop}.count missing: {s}"))
    };
    for hop in HOPS {
        assert!(count(hop) > 100, "{hop} was measured: {s}");
        let (p50, p99, p999, max) = (
            figure(hop, "p50"),
            figure(hop, "p99"),
            figure(hop, "p999"),
            figure(hop, "max"),
        );
        assert!(p50 <= p99 && p99 <= p999 && p999 <= max, "{hop}: {s}");
        assert!(figure(hop, "mean") <= max, "{hop}: {s}");
    }

    // Counts: one sample per message of the hop's kind, as seen on the bus.
    let (sp, tq, st) = (&streams.setpoints, &streams.torques, &streams.states);
    assert_no_gaps("setpoints", sp.iter().map(|m| m.header.seq));
    assert_no_gaps("torques", tq.iter().map(|m| m.header.seq));
    assert_no_gaps("states", st.iter().map(|m| m.header.seq));
    assert_eq!(count("planner_wake_to_setpoint_us"), sp.len() as u64, "{s}");
    assert_eq!(count("setpoint_to_dynamics_us"), tq.len() as u64, "{s}");
    assert_eq!(count("dynamics_compute_us"), tq.len() as u64, "{s}");
    // Plant steps: every state but the initial one and the final (shutdown) one.
    assert!(st.last().is_some_and(|m| m.flags & state_flags::FINAL != 0));
    let steps = st.len() as u64 - 2;
    assert_eq!(count("actuator_step_to_state_us"), steps, "{s}");
    assert_eq!(s["cycles"]["actuator"].as_u64(), Some(steps), "{s}");
    // The torques the actuator took: up to the one its final state names (a torque
    // still in flight at the stop was published but never taken).
    let last_taken = st.last().map_or(u64::MAX, |m| m.torque_seq);
    let (taken, untaken): (Vec<_>, Vec<_>) = tq.iter().partition(|t| t.header.seq <= last_taken);
    let e2e = &s["e2e_latency_us"];
    assert_eq!(e2e["count"].as_u64(), Some(taken.len() as u64), "{s}");
    assert_eq!(count("torque_to_actuator_us"), taken.len() as u64, "{s}");

    // Sums, exact in ns: the services' final statuses against every torque's stamps.
    let dynamics = last_status(&streams.statuses, ServiceRole::Dynamics);
    let actuator = last_status(&streams.statuses, ServiceRole::Actuator);
    let published_ns: u64 = tq.iter().map(setpoint_to_torque_ns).sum();
    let taken_ns: u64 = taken.iter().copied().map(setpoint_to_torque_ns).sum();
    let untaken_ns = published_ns - taken_ns;
    assert_eq!(
        dynamics.hops[0].sum_ns + dynamics.hops[1].sum_ns,
        published_ns,
        "setpoint → dynamics awake + dynamics compute = setpoint stamp → torque stamp"
    );
    assert_eq!(dynamics.latency_sum_ns, published_ns);
    assert_eq!(
        taken_ns + actuator.hops[0].sum_ns,
        actuator.latency_sum_ns,
        "setpoint → torque stamp + torque → actuator = end-to-end"
    );
    for (hop, h) in [
        ("setpoint_to_dynamics_us", dynamics.hops[0]),
        ("dynamics_compute_us", dynamics.hops[1]),
        ("torque_to_actuator_us", actuator.hops[0]),
    ] {
        assert_eq!(count(hop), h.count, "the summary is the final status: {s}");
    }

    // Means: the inside hops' add up to the end-to-end mean, within float rounding once
    // the torques that were never taken are accounted for (µs).
    let n_published = tq.len() as f64;
    let n_taken = taken.len() as f64;
    let e2e_mean = e2e["mean"].as_f64().expect("e2e mean");
    let dyn_total_us = (figure("setpoint_to_dynamics_us", "mean")
        + figure("dynamics_compute_us", "mean"))
        * n_published;
    let rebuilt = (dyn_total_us - untaken_ns as f64 / 1e3) / n_taken
        + figure("torque_to_actuator_us", "mean");
    assert!(
        (rebuilt - e2e_mean).abs() < 1e-6,
        "hops {rebuilt} µs vs end-to-end {e2e_mean} µs: {s}"
    );
    if untaken.is_empty() {
        let sum: f64 = HOPS[1..4].iter().map(|h| figure(h, "mean")).sum();
        assert!((sum - e2e_mean).abs() < 1e-6, "{sum} vs {e2e_mean}: {s}");
    }
}
