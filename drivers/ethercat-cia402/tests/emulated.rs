//! The backend against an emulated chain of CiA 402 drives, in process (no socket, no
//! privileges): bring-up, enable, torque, and every injected fault as the pipeline sees
//! it.

use std::time::Duration;

use microrobot_driver::{ActuatorBackend, Fault, JointVector};
use microrobot_ethercat_cia402::backend::EthercatBackend;
use microrobot_ethercat_cia402::cia402::DriveState;
use microrobot_ethercat_cia402::drive_file::DriveFile;
use microrobot_ethercat_cia402::master::{Transport, codes, pdu_loop};
use microrobot_ethercat_emulator::{ChainConfig, Emulator, Fault as Inject, InProcessLink};

mod common;
use common::{drive_file, drive_file_with_watchdog};

const JOINTS: [&str; 6] = ["j1", "j2", "j3", "j4", "j5", "j6"];

/// A backend on the in-process link to `emulator`; every bring-up opens a new link.
fn backend(emulator: &Emulator, file: DriveFile) -> EthercatBackend {
    let n = file.axes.len();
    let emulator = emulator.clone();
    let connect = Box::new(move || {
        let (tx, rx, pdu_loop) = pdu_loop()?;
        let link = InProcessLink::spawn(emulator.clone(), tx, rx).expect("link thread");
        Ok(Transport::new(pdu_loop, move || link.stop()))
    });
    // A loaded test machine: a generous exchange deadline (simulated time advances per
    // exchange, so it changes nothing else).
    EthercatBackend::new(file, &JOINTS[..n], connect)
        .expect("backend")
        .with_exchange_timeout(Duration::from_millis(20))
}

fn cycle(b: &mut EthercatBackend, tau: &JointVector) -> Result<microrobot_driver::Measured, Fault> {
    b.write(0, 1e-3, tau)?;
    b.read(0)
}

fn active(emulator: &Emulator, n: usize) -> EthercatBackend {
    let mut b = backend(emulator, drive_file(n, 1.27));
    b.on_configure().expect("configure");
    b.read(0).expect("first read");
    b.on_activate().expect("activate");
    b
}

/// Cycles until a fault comes back (at most `n`).
fn fault_within(b: &mut EthercatBackend, n: usize) -> Fault {
    let tau = JointVector::zeros();
    for _ in 0..n {
        if let Err(f) = cycle(b, &tau) {
            return f;
        }
    }
    panic!("no fault within {n} cycles");
}

#[test]
fn seed_arm_reaches_op_enables_and_a_torque_moves_the_joint() {
    let e = Emulator::new(&ChainConfig::seed_arm()).expect("chain");
    let mut b = active(&e, 6);
    assert!(b.axes().iter().all(|a| a.is_enabled()));
    for i in 0..6 {
        let d = e.drive(i).expect("drive");
        assert_eq!(d.state, DriveState::OperationEnabled);
        assert_eq!(d.mode, 10, "CST");
        assert_eq!(d.al_state, 8, "OP");
    }
    let bus = b.bus().expect("bus");
    assert_eq!(bus.expected_working_counter(), 18);
    println!("distributed clocks: {}", bus.distributed_clocks());

    let m0 = cycle(&mut b, &JointVector::zeros()).expect("cycle");
    let mut tau = JointVector::zeros();
    tau[0] = 0.5; // N·m joint side: 5 per mille of 1.27 N·m over gear 100 → 4 ‰.
    let mut m = m0;
    let before = b.exchange_stats();
    for _ in 0..300 {
        m = cycle(&mut b, &tau).expect("cycle");
    }
    let after = b.exchange_stats();
    let d0 = e.drive(0).expect("drive 0");
    assert!(m.q[0] - m0.q[0] > 0.01, "j1 moved {} rad", m.q[0] - m0.q[0]);
    assert!(
        (m.q[0] - d0.position_rad).abs() < 0.01,
        "measured {} vs plant {}",
        m.q[0],
        d0.position_rad
    );
    assert!(m.qd[0] > 0.0);
    assert!(d0.torque_nm > 0.0, "the drive applies torque");
    // The torque applied is the one commanded, as the drive receives it: 0x6071 after
    // the per-mille quantisation, in the same cycle (not the torque actual a cycle late).
    let s = &drive_file(6, 1.27).axes[0].scaling;
    let sent = s.effort_from_torque_actual(s.effort_to_target_torque(0.5).per_mille);
    assert_eq!(m.tau_applied[0], sent, "tau applied");
    assert!((sent - 0.5).abs() < 0.1, "tau applied {sent}");
    tau[0] = -0.3;
    let m = cycle(&mut b, &tau).expect("cycle");
    assert_eq!(
        m.tau_applied[0],
        s.effort_from_torque_actual(s.effort_to_target_torque(-0.3).per_mille),
        "the command of this cycle"
    );
    let n = (after.count - before.count) as f64;
    println!(
        "in-process exchange, 6 drives: mean {:.1} µs, max {:.1} µs over {n} cycles, {} lost",
        (after.total_s - before.total_s) / n * 1e6,
        after.max_s * 1e6,
        after.lost
    );

    b.on_deactivate().expect("deactivate");
    assert!((0..6).all(|i| e.drive(i).expect("drive").state == DriveState::SwitchOnDisabled));
    b.on_shutdown();
    assert!((0..6).all(|i| e.drive(i).expect("drive").al_state != 8));
}

#[test]
fn a_drive_fault_is_its_joint_and_code_and_a_reset_recovers() {
    let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
    let mut b = active(&e, 3);
    e.inject(Inject::DriveFault {
        drive: 1,
        error_code: 0x2310,
    })
    .expect("inject");
    let f = fault_within(&mut b, 5);
    assert_eq!((f.joint, f.code), (Some(1), 0x2310), "{f}");
    b.on_error(&f);
    // The others stop; the bus keeps running while the framework is in Fault.
    for _ in 0..20 {
        let _ = b.read(0);
    }
    assert_ne!(e.drive(0).expect("d0").state, DriveState::OperationEnabled);
    b.on_reset().expect("reset");
    assert_eq!(e.drive(1).expect("d1").error_code, 0);
    assert!(b.read(0).is_ok());
    b.on_activate().expect("activate again");
    assert!(b.axes().iter().all(|a| a.is_enabled()));
}

#[test]
fn a_drive_leaving_op_is_its_joint_with_the_al_status_code_and_a_reset_brings_the_bus_up() {
    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let mut b = active(&e, 2);
    e.inject(Inject::DropOutOfOp {
        drive: 1,
        al_status_code: 0x001B,
    })
    .expect("inject");
    let f = fault_within(&mut b, 5);
    assert_eq!((f.joint, f.code), (Some(1), codes::left_op(0x001B)), "{f}");
    b.on_error(&f);
    b.on_reset().expect("reset: bus up again");
    b.on_activate().expect("activate again");
    assert_eq!(e.drive(1).expect("d1").al_state, 8);
    assert!(cycle(&mut b, &JointVector::zeros()).is_ok());
}

/// The master stops exchanging (its process died, or hangs): each drive's own process
/// data watchdog (ESC 0x0420 as the drive file arms it) takes the torque off and faults
/// the enabled drive, which leaves OP with the SM watchdog code. The next exchange
/// reports it, and a reset brings the bus up, clears the drive fault and re-enables.
#[test]
fn a_silent_master_trips_the_drives_watchdog_and_a_reset_recovers() {
    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let mut b = backend(&e, drive_file_with_watchdog(2, 1.27, 30));
    b.on_configure().expect("configure");
    b.read(0).expect("first read");
    b.on_activate().expect("activate");
    let mut tau = JointVector::zeros();
    tau[0] = 10.0;
    cycle(&mut b, &tau).expect("torque");
    cycle(&mut b, &tau).expect("torque");
    assert!(e.drive(0).expect("d0").torque_nm > 1.0, "torque applied");
    // Well past 30 ms without a frame (the in-process link runs the watchdogs every 2 ms).
    std::thread::sleep(Duration::from_millis(200));
    for i in 0..2 {
        let d = e.drive(i).expect("drive");
        assert_eq!(
            (d.al_state, d.al_error, d.al_status_code),
            (4, true, 0x001B),
            "drive {i} left OP on its watchdog"
        );
        assert!(d.state.is_fault(), "drive {i}: {:?}", d.state);
        assert_eq!(d.error_code, 0x8130, "drive {i}");
        assert_eq!(d.torque_nm, 0.0, "drive {i}: torque off");
    }
    let f = cycle(&mut b, &tau).expect_err("the drives left OP");
    assert_eq!((f.joint, f.code), (Some(0), codes::left_op(0x001B)), "{f}");
    b.on_error(&f);
    b.on_reset().expect("reset: bus up, drive faults cleared");
    b.on_activate().expect("enabled again");
    cycle(&mut b, &JointVector::zeros()).expect("cycling again");
    assert_eq!(e.drive(1).expect("d1").error_code, 0);
}

#[test]
fn lost_and_late_frames_are_ridden_out_up_to_max_lost_cycles() {
    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let mut b = active(&e, 2); // max_lost_cycles = 3
    let tau = JointVector::zeros();
    e.inject(Inject::LoseFrames { count: 3 }).expect("inject");
    for _ in 0..3 {
        cycle(&mut b, &tau).expect("a lost cycle within the limit");
    }
    cycle(&mut b, &tau).expect("back");
    assert_eq!(b.exchange_stats().lost, 3);
    e.inject(Inject::DelayFrames {
        delay: Duration::from_millis(60),
        count: 1,
    })
    .expect("inject");
    cycle(&mut b, &tau).expect("one late frame is one lost cycle");
    assert_eq!(b.exchange_stats().lost, 4);
    for _ in 0..5 {
        cycle(&mut b, &tau).expect("after the late frame");
    }
    e.inject(Inject::LoseFrames { count: 4 }).expect("inject");
    for _ in 0..3 {
        cycle(&mut b, &tau).expect("within the limit");
    }
    let f = cycle(&mut b, &tau).expect_err("the fourth in a row");
    assert_eq!((f.joint, f.code), (None, codes::BUS_LOST), "{f}");
}

#[test]
fn a_link_down_is_a_fault_and_a_reset_after_link_up_recovers() {
    let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
    let mut b = active(&e, 3);
    e.inject(Inject::LinkDown { position: 2 }).expect("inject");
    let f = fault_within(&mut b, 5);
    assert!(
        f.code == codes::WORKING_COUNTER || (f.code & 0xFFFF_0000) == codes::LEFT_OP,
        "{f}"
    );
    b.on_error(&f);
    e.inject(Inject::ClearLink).expect("inject");
    b.on_reset().expect("reset");
    b.on_activate().expect("activate again");

    e.inject(Inject::LinkDown { position: 0 }).expect("inject");
    let f = fault_within(&mut b, 10);
    assert_eq!((f.joint, f.code), (None, codes::BUS_LOST), "{f}");
}

#[test]
fn a_wrong_identity_is_refused_before_anything_is_written() {
    let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
    e.inject(Inject::WrongIdentity {
        drive: 2,
        vendor_id: 0x0000_0002,
        product_code: 0x0BAD_0BAD,
    })
    .expect("inject");
    let mut b = backend(&e, drive_file(3, 1.27));
    let f = b.on_configure().expect_err("wrong identity");
    assert_eq!((f.joint, f.code), (Some(2), codes::WRONG_IDENTITY), "{f}");
    for s in ["j3", "0x00000002", "0x0bad0bad", "0x0000009a", "0x00030924"] {
        assert!(f.text.contains(s), "{s} in {f}");
    }
    for i in 0..3 {
        let d = e.drive(i).expect("drive");
        assert_eq!(d.mode, 0, "no mode written to drive {i}");
        assert_ne!(d.al_state, 8);
        assert_eq!(d.state, DriveState::SwitchOnDisabled);
    }
}

#[test]
fn a_wrong_count_or_rated_torque_is_refused_naming_it() {
    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let f = backend(&e, drive_file(3, 1.27))
        .on_configure()
        .expect_err("3 axes, 2 drives");
    assert_eq!(f.code, codes::AXIS_COUNT, "{f}");
    assert!(
        f.text.contains("2 SubDevices") && f.text.contains("3 axes"),
        "{f}"
    );

    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let f = backend(&e, drive_file(2, 1.5))
        .on_configure()
        .expect_err("rated torque");
    assert_eq!((f.joint, f.code), (Some(0), codes::RATED_TORQUE), "{f}");
    assert!(
        f.text.contains("1270 mN·m") && f.text.contains("1.5 N·m"),
        "{f}"
    );
}

#[test]
fn bring_up_sets_dc_sync0_mode_and_the_cycle_time_in_pre_op() {
    let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
    let mut b = active(&e, 3);
    assert!(b.bus().expect("bus").distributed_clocks());
    for i in 0..3 {
        let d = e.drive(i).expect("drive");
        assert_eq!((d.sync_mode, d.cycle_time_ns), (2, 1_000_000), "drive {i}");
        assert_eq!(d.al_state, 8);
    }
    b.on_shutdown();
}

#[test]
fn a_cycle_below_a_drives_minimum_cycle_time_is_refused_naming_the_axis() {
    let mut chain = ChainConfig::inertia_chain(3);
    chain.drives[1].min_cycle_time_ns = 2_000_000;
    let e = Emulator::new(&chain).expect("chain");
    let f = backend(&e, drive_file(3, 1.27))
        .on_configure()
        .expect_err("1 ms is below 2 ms");
    assert_eq!((f.joint, f.code), (Some(1), codes::DC_CONFIG), "{f}");
    for part in [
        "axis 1",
        "joint j2",
        "bus position 1",
        "0x1C32:05 = 2000000 ns",
        "1000 µs",
    ] {
        assert!(f.text.contains(part), "{part}: {f}");
    }
    // Refused before the sync mode was written, and nothing reached OP.
    let d = e.drive(1).expect("drive");
    assert_eq!(d.sync_mode, 0);
    assert!((0..3).all(|i| e.drive(i).expect("drive").al_state != 8));
}

/// On the wall clock the drives take their outputs at SYNC0. The pipeline's exchanges
/// come at a phase of their own and the drives' clocks run 100 ppm fast: the master
/// moves SYNC0 onto the exchanges and keeps it there, and no SM event is missed but
/// for an exchange the master itself saw arrive after its SYNC0 or lost (the test
/// thread or the link thread descheduled for more than the 10 ms margin on a loaded
/// machine).
#[test]
fn a_steady_dc_run_keeps_sync0_after_the_exchange_and_misses_no_sm_event() {
    use std::time::Instant;
    let mut chain = ChainConfig::inertia_chain(2);
    chain.time = microrobot_ethercat_emulator::TimeMode::WallClock { max_step_s: 0.05 };
    chain.dc_drift_ppm = 100.0;
    let e = Emulator::new(&chain).expect("chain");
    // A 20 ms cycle: SYNC0 10 ms after the exchange, so that a loaded test machine's
    // late wake-ups (the other tests run beside this one) stay inside the margin.
    let text = include_str!("../example.drive.toml").replace("cycle_us = 1000", "cycle_us = 20000");
    let mut parts = text.split("\n[[axis]]\n");
    let mut file = parts.next().expect("bus").to_string();
    for p in parts.take(2) {
        file.push_str("\n[[axis]]\n");
        file.push_str(&p.replace("drive_watchdog_ms = 10", "drive_watchdog_ms = 1000"));
    }
    let file = DriveFile::from_toml_str(&file, "test.drive.toml").expect("drive file");
    // An exchange later than 15 ms is lost; one between 10 and 15 ms late is measured
    // past its SYNC0: every SYNC0 a frame can miss is one or the other.
    let mut b = backend(&e, file).with_exchange_timeout(Duration::from_millis(15));
    b.on_configure().expect("configure");
    b.read(0).expect("first read");
    b.on_activate().expect("activate");
    let period = Duration::from_millis(20);
    // The pipeline's phase: 3.7 ms off whatever the bring-up had.
    std::thread::sleep(Duration::from_micros(3700));
    let mut next = Instant::now();
    let mut run = |b: &mut EthercatBackend, n: usize| {
        let mut tau = JointVector::zeros();
        tau[0] = 0.2;
        for _ in 0..n {
            // As the actuator's timer: periods missed while descheduled are skipped,
            // not replayed in a burst.
            next += period;
            while next < Instant::now() {
                next += period;
            }
            if let Some(w) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(w);
            }
            cycle(b, &tau).expect("cycle");
        }
    };
    // The phase is taken in the first windows (8 exchanges at 20 ms).
    run(&mut b, 30);
    let p0 = b.bus().and_then(|b| b.phase()).expect("DC phase");
    // Moved onto the exchanges (an acquisition, or slewed when the pipeline's phase
    // happened to fall within the lock window).
    let err0 = p0.window_median_margin_ns as i64 - p0.target_margin_ns as i64;
    assert!(err0.abs() < 2_500_000, "{p0:?}");
    let before: Vec<_> = (0..2).map(|i| e.drive(i).expect("drive")).collect();
    let lost0 = b.exchange_stats().lost;
    run(&mut b, 150);
    let lost = b.exchange_stats().lost - lost0;
    let p = b.bus().and_then(|b| b.phase()).expect("DC phase");
    println!("phase after acquisition {p0:?}\nafter 150 more exchanges {p:?}");
    let late = p.late - p0.late;
    assert!(late <= 3, "{late} of 150 exchanges past their SYNC0: {p:?}");
    for (i, d0) in before.iter().enumerate() {
        let d = e.drive(i).expect("drive");
        let missed = u64::from(d.sm_event_missed - d0.sm_event_missed);
        assert!(
            missed <= late + lost,
            "drive {i}: {missed} SM events missed, {late} exchanges past their SYNC0, {lost} lost"
        );
        assert!(
            d.sync0_latched - d0.sync0_latched >= 145,
            "drive {i}: outputs taken at {} SYNC0 events",
            d.sync0_latched - d0.sync0_latched
        );
    }
    assert_eq!(p.acquisitions, p0.acquisitions, "no new acquisition: {p:?}");
    // Kept at the 10 ms target against 100 ppm (2 µs per cycle) of drift: the median
    // of the last window within 1 ms, nine in ten margins within the lock window
    // (period / 8; the test thread's late wake-ups on a loaded machine spread them).
    assert_eq!(p.target_margin_ns, 10_000_000);
    let err = p.window_median_margin_ns as i64 - p.target_margin_ns as i64;
    assert!(err.abs() < 1_000_000, "{p:?}");
    for q in [0.05, 0.95] {
        let m = p.margin_quantile_ns(q).expect("margins") as i64;
        assert!((m - 10_000_000).abs() <= 2_500_000, "q {q}: {m} ns, {p:?}");
    }
    assert!(p.corrections > p0.corrections, "drift followed: {p:?}");
    // The drives' counters read back over SDO agree with the emulator.
    let counters = b.bus().expect("bus").sync_counters();
    for (i, c) in counters.iter().enumerate() {
        let c = c.expect("0x1C32:0B readable");
        assert_eq!(
            c.sm_event_missed,
            e.drive(i).expect("drive").sm_event_missed
        );
    }
    b.on_shutdown();
}
