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

const JOINTS: [&str; 6] = ["j1", "j2", "j3", "j4", "j5", "j6"];

/// The example drive file with its first `n` axes and `rated_j1` as joint 1's rated
/// torque. The drives' watchdog is 1 s (the example's 10 ms would expire whenever the
/// loaded test machine deschedules the test thread between two cycles).
fn drive_file(n: usize, rated_j1: f64) -> DriveFile {
    drive_file_with_watchdog(n, rated_j1, 1000)
}

fn drive_file_with_watchdog(n: usize, rated_j1: f64, watchdog_ms: u32) -> DriveFile {
    let text = include_str!("../example.drive.toml").replace(
        "drive_watchdog_ms = 10",
        &format!("drive_watchdog_ms = {watchdog_ms}"),
    );
    let mut parts = text.split("\n[[axis]]\n");
    let mut out = parts.next().expect("bus table").to_string();
    for (i, p) in parts.take(n).enumerate() {
        out.push_str("\n[[axis]]\n");
        if i == 0 {
            out.push_str(&p.replace(
                "rated_torque_nm = 1.27",
                &format!("rated_torque_nm = {rated_j1}"),
            ));
        } else {
            out.push_str(p);
        }
    }
    DriveFile::from_toml_str(&out, "test.drive.toml").expect("drive file")
}

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
