//! The PDU storage across bring-ups: one storage however often the bus comes up. One
//! test in its own binary, so no other test's transport takes or makes storages
//! meanwhile.

use std::time::Duration;

use microrobot_driver::{ActuatorBackend, JointVector};
use microrobot_ethercat_cia402::backend::EthercatBackend;
use microrobot_ethercat_cia402::drive_file::DriveFile;
use microrobot_ethercat_cia402::master::{Transport, codes, pdu_loop, pdu_storages};
use microrobot_ethercat_emulator::{ChainConfig, Emulator, Fault as Inject, InProcessLink};

mod common;

/// The example drive file's first two axes (the drives' watchdog at 1 s).
fn drive_file() -> DriveFile {
    common::drive_file(2, 1.27)
}

fn backend(e: &Emulator) -> EthercatBackend {
    let emulator = e.clone();
    let connect = Box::new(move || {
        let (tx, rx, pdu_loop) = pdu_loop()?;
        let link = InProcessLink::spawn(emulator.clone(), tx, rx).expect("link thread");
        Ok(Transport::new(pdu_loop, move || link.stop()))
    });
    EthercatBackend::new(drive_file(), &["j1", "j2"], connect)
        .expect("backend")
        .with_exchange_timeout(Duration::from_millis(20))
}

#[test]
fn bring_ups_and_resets_reuse_one_pdu_storage() {
    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    assert_eq!(pdu_storages(), 0);
    // Bus up and down, a new backend each time (a restarted configure).
    for _ in 0..10 {
        let mut b = backend(&e);
        b.on_configure().expect("configure");
        b.read(0).expect("a cycle");
        b.on_shutdown();
    }
    assert_eq!(pdu_storages(), 1, "one storage for ten bring-ups");
    // A bus fault and a reset: the bus comes up again on a new transport, each time.
    let mut b = backend(&e);
    b.on_configure().expect("configure");
    b.on_activate().expect("activate");
    for _ in 0..5 {
        e.inject(Inject::LinkDown { position: 0 }).expect("inject");
        let f = (0..10)
            .find_map(|_| {
                b.write(0, 1e-3, &JointVector::zeros()).ok()?;
                b.read(0).err()
            })
            .expect("the link down is a fault");
        assert_eq!(f.code, codes::BUS_LOST, "{f}");
        b.on_error(&f);
        e.inject(Inject::ClearLink).expect("inject");
        b.on_reset().expect("reset: the bus up again");
        b.on_activate().expect("activate again");
    }
    assert_eq!(pdu_storages(), 1, "and for five resets");
    drop(b);
    // Without the hand-back a transport whose link gives nothing back loses its storage:
    // the next bring-up makes a new one (what every bring-up did before).
    let (tx, rx, md_loop) = pdu_loop().expect("the idle loop");
    let link = InProcessLink::spawn(e.clone(), tx, rx).expect("link thread");
    drop(Transport::new(md_loop, move || {
        drop(link);
        None
    }));
    let _ = pdu_loop().expect("a new storage");
    assert_eq!(pdu_storages(), 2);
}
