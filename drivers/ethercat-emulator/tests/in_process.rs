//! An unchanged ethercrab MainDevice against the emulated chain over the in-process
//! link: discovery, SDO, OP, cyclic data, CiA 402 enable, torque, and every fault.

mod common;

use async_io::{Timer, block_on};
use common::{MAX_SUBDEVICES, PDI_LEN, PDU_TIMEOUT, bus, cycle};
use ethercrab::error::{Error, MailboxError};
use ethercrab::std::ethercat_now;
use ethercrab::{AlStatusCode, SubDeviceState, error::CoeAbortCode};
use microrobot_ethercat_cia402::cia402::{Axis, AxisFault, DriveState, Statusword, Target};
use microrobot_ethercat_emulator::config::{SEED_PRODUCT_CODE, SEED_VENDOR_ID};
use microrobot_ethercat_emulator::{ChainConfig, Fault, MODE_CSP, MODE_CST};

#[test]
fn seed_arm_is_discovered_configured_enabled_and_moves() {
    let b = bus(&ChainConfig::seed_arm());
    let md = &b.maindevice;
    block_on(async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now)
            .await
            .expect("discovery to PRE-OP");
        assert_eq!(group.len(), 6);
        for (i, sd) in group.iter(md).enumerate() {
            assert_eq!(sd.name(), format!("MR-SERVO-J{}", i + 1));
            let id = sd.identity();
            assert_eq!(
                (id.vendor_id, id.product_id),
                (SEED_VENDOR_ID, SEED_PRODUCT_CODE)
            );
            assert_eq!(id.serial, 0x1000 + i as u32);
            assert_eq!(sd.sdo_read::<u32>(0x1018, 1).await, Ok(SEED_VENDOR_ID));
            assert_eq!(sd.sdo_read::<u32>(0x1000, 0).await, Ok(0x0002_0192));
            // More than 4 bytes: a normal (not expedited) upload.
            let name = format!("MR-SERVO-J{}", i + 1);
            assert_eq!(
                sd.sdo_read::<[u8; 11]>(0x1008, 0)
                    .await
                    .as_ref()
                    .map(|n| &n[..]),
                Ok(name.as_bytes())
            );
            let rated_mnm = if i < 3 { 1270 } else { 640 };
            assert_eq!(sd.sdo_read::<u32>(0x6076, 0).await, Ok(rated_mnm));
            sd.sdo_write(0x6060, 0, MODE_CST).await.expect("mode CST");
            assert_eq!(sd.sdo_read::<i8>(0x6060, 0).await, Ok(MODE_CST));
            // The PDO assignment and mapping, written the way masters write them.
            sd.sdo_write(0x1C12, 0, 0u8)
                .await
                .expect("clear assignment");
            sd.sdo_write(0x1600, 0, 0u8).await.expect("clear mapping");
            for (sub, entry) in [0x6040_0010u32, 0x6071_0010, 0x607A_0020]
                .into_iter()
                .enumerate()
            {
                sd.sdo_write(0x1600, sub as u8 + 1, entry)
                    .await
                    .expect("entry");
            }
            sd.sdo_write(0x1600, 0, 3u8).await.expect("mapping");
            sd.sdo_write(0x1C12, 1, 0x1600u16).await.expect("assign");
            sd.sdo_write(0x1C12, 0, 1u8).await.expect("assignment");
        }
        let sd0 = group.subdevice(md, 0).expect("drive 0");
        match sd0.sdo_read::<u32>(0x2000, 0).await {
            Err(Error::Mailbox(MailboxError::Aborted { code, .. })) => {
                assert_eq!(code, CoeAbortCode::NotFound)
            }
            other => panic!("unknown object: {other:?}"),
        }
        match sd0.sdo_write(0x6060, 0, 3i8).await {
            Err(Error::Mailbox(MailboxError::Aborted { code, .. })) => {
                assert_eq!(u32::from(code), 0x0609_0030)
            }
            other => panic!("unsupported mode: {other:?}"),
        }

        let group = group.into_op(md).await.expect("OP");
        let mut axes = vec![Axis::new(); 6];
        for a in axes.iter_mut() {
            a.set_target(Target::Enabled);
        }
        let start = b.emulator.drive(0).expect("drive 0").position_counts;
        let mut torque = [0i16; 6];
        let mut last = Vec::new();
        let t0 = std::time::Instant::now();
        for n in 0..300 {
            let (resp, inputs) = cycle(&group, md, &mut axes, &torque).await.expect("cycle");
            assert_eq!(resp.working_counter, 18, "LRW: 6 × (read 1 + write 2)");
            assert!(resp.all_op());
            if n == 10 {
                assert!(inputs.iter().all(|i| i.step.fault.is_none()));
                assert!(
                    axes.iter().all(|a| a.is_enabled()),
                    "enabled within 10 cycles"
                );
                torque[0] = 5;
            }
            last = inputs;
        }
        let moved = last[0].position_counts.wrapping_sub(start);
        // 0.005 × 1.27 N·m × 100 on the base joint for ~0.29 s moves it by many counts
        // (2^20 per motor revolution, ×100 gear) and stays inside its limits.
        assert!(moved > 100_000, "base joint moved {moved} counts");
        assert!(b.emulator.drive(0).expect("drive 0").position_rad < 3.0);
        assert!(
            last[0].velocity_counts_s > 0,
            "moved {moved}, {:?}, {:?}",
            last[0],
            b.emulator.drive(0)
        );
        assert_eq!(last[0].torque_per_mille, 5);
        assert_eq!(
            b.emulator.drive(0).expect("drive 0").state,
            DriveState::OperationEnabled
        );
        println!(
            "300 cycles in {:?} ({:.1} µs per tx_rx); base joint {moved} counts in 290 cycles; frames {:?}",
            t0.elapsed(),
            t0.elapsed().as_secs_f64() * 1e6 / 300.0,
            b.emulator.counters()
        );
    });
}

#[test]
fn injected_faults_are_seen_as_on_hardware() {
    let b = bus(&ChainConfig::inertia_chain(2));
    let md = &b.maindevice;
    let e = &b.emulator;
    block_on(async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now)
            .await
            .expect("PRE-OP");
        for sd in group.iter(md) {
            sd.sdo_write(0x6060, 0, MODE_CST).await.expect("mode");
        }
        let group = group.into_op(md).await.expect("OP");
        let mut axes = vec![Axis::new(); 2];
        for a in axes.iter_mut() {
            a.set_target(Target::Enabled);
        }
        let torque = [0i16; 2];
        for _ in 0..10 {
            cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        }
        assert!(axes.iter().all(|a| a.is_enabled()));

        // A drive fault: fault bit and error code, then a fault reset on request.
        e.inject(Fault::DriveFault {
            drive: 1,
            error_code: 0x2310,
        })
        .expect("drive 1");
        // The inputs the master reads were latched at the previous exchange: the fault
        // shows one cycle later, as on a drive that samples once per cycle.
        cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        let (_, inputs) = cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        assert_eq!(inputs[1].statusword & 0x0008, 0x0008, "fault bit");
        assert_eq!(inputs[1].error_code, 0x2310);
        assert!(matches!(
            inputs[1].step.fault,
            Some(AxisFault::Drive {
                error_code: 0x2310,
                ..
            })
        ));
        axes[1].reset();
        for _ in 0..10 {
            cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        }
        assert!(axes[1].is_enabled(), "re-enabled after the fault reset");
        assert_eq!(e.drive(1).expect("drive 1").error_code, 0);

        // Lost frames: the master times out, the next exchange works.
        e.inject(Fault::LoseFrames { count: 1 }).expect("lose");
        let r = group.tx_rx(md).await;
        assert!(matches!(r, Err(Error::Timeout(_))), "{r:?}");
        assert_eq!(
            group.tx_rx(md).await.expect("after loss").working_counter,
            6
        );

        // A late frame (twice the PDU timeout) is a timeout too.
        e.inject(Fault::DelayFrames {
            delay: 2 * PDU_TIMEOUT,
            count: 1,
        })
        .expect("delay");
        let r = group.tx_rx(md).await;
        assert!(matches!(r, Err(Error::Timeout(_))), "{r:?}");
        // The link answers other frames while it holds the late one.
        assert_eq!(group.tx_rx(md).await.expect("next").working_counter, 6);
        Timer::after(PDU_TIMEOUT).await;
        assert_eq!(
            group.tx_rx(md).await.expect("after delay").working_counter,
            6
        );

        // Link down behind drive 0: only drive 0 counts; in front of it: silence.
        e.inject(Fault::LinkDown { position: 1 }).expect("link");
        assert_eq!(
            group.tx_rx(md).await.expect("half chain").working_counter,
            3
        );
        e.inject(Fault::LinkDown { position: 0 }).expect("link");
        assert!(matches!(group.tx_rx(md).await, Err(Error::Timeout(_))));
        e.inject(Fault::ClearLink).expect("clear");
        assert_eq!(group.tx_rx(md).await.expect("link up").working_counter, 6);

        // A drive drops out of OP: working counter short by its outputs, AL status
        // SAFE-OP with error and code, and its power stage faults.
        e.inject(Fault::DropOutOfOp {
            drive: 0,
            al_status_code: 0x001B,
        })
        .expect("drop");
        let (resp, inputs) = cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        assert_eq!(resp.working_counter, 4);
        assert!(!resp.all_op());
        assert_eq!(resp.subdevice_states[0], SubDeviceState::SafeOp);
        let sd0 = group.subdevice(md, 0).expect("drive 0");
        assert_eq!(
            sd0.status().await,
            Err(Error::SubDevice(AlStatusCode::SyncManagerWatchdog))
        );
        let (_, inputs2) = cycle(&group, md, &mut axes, &torque).await.expect("cycle");
        let _ = inputs;
        assert_eq!(
            inputs2[0].error_code,
            microrobot_ethercat_emulator::ERROR_COMMUNICATION
        );
        assert!(axes[1].is_enabled(), "the other drive runs on");

        // The master acknowledges the error with its request for OP (AL control
        // 0x0120: OP | acknowledge), then resets the drive's fault.
        sd0.register_write(0x0120u16, 0x0018u16)
            .await
            .expect("acknowledge");
        assert_eq!(
            sd0.status().await,
            Ok((SubDeviceState::Op, AlStatusCode::NoError))
        );
        axes[0].reset();
        for _ in 0..10 {
            let (resp, _) = cycle(&group, md, &mut axes, &torque).await.expect("cycle");
            assert_eq!(resp.working_counter, 6);
        }
        assert!(axes[0].is_enabled(), "drive 0 back in operation");
        assert!(e.counters().dropped_by_fault >= 2);
    });
}

#[test]
fn wrong_identity_is_visible_at_discovery() {
    let b = bus(&ChainConfig::inertia_chain(3));
    b.emulator
        .inject(Fault::WrongIdentity {
            drive: 2,
            vendor_id: 0x0000_0002,
            product_code: 0x0BAD_0BAD,
        })
        .expect("drive 2");
    assert!(
        b.emulator
            .inject(Fault::DriveFault {
                drive: 3,
                error_code: 1
            })
            .is_err()
    );
    let md = &b.maindevice;
    block_on(async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now)
            .await
            .expect("PRE-OP");
        let ids: Vec<_> = group
            .iter(md)
            .map(|sd| (sd.identity().vendor_id, sd.identity().product_id))
            .collect();
        assert_eq!(ids[0], (SEED_VENDOR_ID, SEED_PRODUCT_CODE));
        assert_eq!(ids[2], (0x0000_0002, 0x0BAD_0BAD));
        let sd2 = group.subdevice(md, 2).expect("drive 2");
        assert_eq!(sd2.sdo_read::<u32>(0x1018, 2).await, Ok(0x0BAD_0BAD));
    });
}

#[test]
fn a_link_down_chain_is_not_discovered() {
    let b = bus(&ChainConfig::inertia_chain(2));
    b.emulator
        .inject(Fault::LinkDown { position: 0 })
        .expect("link");
    let r = block_on(
        b.maindevice
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now),
    );
    assert!(matches!(r, Err(Error::Timeout(_))), "{:?}", r.err());
}

#[test]
fn csp_mode_follows_the_target_position() {
    let b = bus(&ChainConfig::inertia_chain(1));
    let md = &b.maindevice;
    block_on(async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now)
            .await
            .expect("PRE-OP");
        let sd = group.subdevice(md, 0).expect("drive 0");
        sd.sdo_write(0x6060, 0, MODE_CSP).await.expect("mode CSP");
        let group = group.into_op(md).await.expect("OP");
        let mut axis = Axis::new();
        axis.set_target(Target::Enabled);
        // 0.1 rad at the joint: 2^20 counts per motor revolution, gear 100.
        let target = (0.1 * f64::from(1u32 << 20) * 100.0 / std::f64::consts::TAU) as i32;
        let mut last = None;
        for _ in 0..400 {
            group.tx_rx(md).await.expect("cycle");
            let sd = group.subdevice(md, 0).expect("drive 0");
            let mut io = sd.io_raw_mut();
            let inp = io.inputs().to_vec();
            let sw = Statusword(u16::from_le_bytes([inp[0], inp[1]]));
            let step = axis.step(sw.state().expect("defined"), 0);
            let out = io.outputs();
            out[0..2].copy_from_slice(&step.controlword.bits().to_le_bytes());
            out[4..8].copy_from_slice(&target.to_le_bytes());
            last = Some(i32::from_le_bytes([inp[2], inp[3], inp[4], inp[5]]));
        }
        let reached = last.expect("cycles ran");
        let error = (reached - target).abs();
        assert!(
            error < target / 100,
            "position {reached} for target {target}"
        );
        assert_eq!(b.emulator.drive(0).expect("drive 0").mode, MODE_CSP);
    });
}

/// The SyncManager parameters over CoE (ETG.1020): read, a sync mode the drive does not
/// offer aborted, DC SYNC0 written in PRE-OP; without SYNC0 activated the drive then
/// refuses OP with AL status code 0x0030.
#[test]
fn dc_sync_mode_over_coe_and_op_refused_without_sync0() {
    let b = bus(&ChainConfig::inertia_chain(1));
    let md = &b.maindevice;
    block_on(async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercat_now)
            .await
            .expect("discovery to PRE-OP");
        let sd = group.subdevice(md, 0).expect("drive 0");
        assert_eq!(sd.sdo_read::<u16>(0x1C32, 4).await, Ok(0x0007));
        assert_eq!(sd.sdo_read::<u32>(0x1C32, 5).await, Ok(125_000));
        assert_eq!(sd.sdo_read::<u16>(0x1C33, 1).await, Ok(0));
        match sd.sdo_write(0x1C32, 1, 3u16).await {
            Err(Error::Mailbox(MailboxError::Aborted { code, .. })) => {
                assert_eq!(u32::from(code), 0x0609_0030, "SYNC1 not offered")
            }
            other => panic!("sync mode 3: {other:?}"),
        }
        match sd.sdo_write(0x1C32, 5, 1000u32).await {
            Err(Error::Mailbox(MailboxError::Aborted { code, .. })) => {
                assert_eq!(u32::from(code), 0x0601_0002, "read only")
            }
            other => panic!("minimum cycle time: {other:?}"),
        }
        sd.sdo_write(0x1C32, 1, 2u16).await.expect("DC SYNC0");
        sd.sdo_write(0x1C32, 2, 1_000_000u32).await.expect("cycle");
        assert_eq!(sd.sdo_read::<u16>(0x1C32, 1).await, Ok(2));
        assert!(group.into_op(md).await.is_err(), "no SYNC0: no OP");
    });
    let d = b.emulator.drive(0).expect("drive 0");
    assert_eq!(
        (d.al_state, d.al_error, d.al_status_code),
        (4, true, 0x0030),
        "SAFE-OP, invalid DC SYNC configuration"
    );
}
