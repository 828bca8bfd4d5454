//! Shared by the tests: an unchanged ethercrab MainDevice on the in-process link, and
//! one cyclic exchange driving every axis with the master-side CiA 402 core.

#![allow(dead_code)]

use std::time::Duration;

use ethercrab::subdevice_group::Op;
use ethercrab::{
    DefaultLock, MainDevice, MainDeviceConfig, PduStorage, SubDeviceGroup, Timeouts, TxRxResponse,
    error::Error,
};
use microrobot_ethercat_cia402::cia402::{Axis, Statusword, Step};
use microrobot_ethercat_emulator::{ChainConfig, Emulator, InProcessLink};

pub const MAX_SUBDEVICES: usize = 8;
/// PDU (and EEPROM busy-wait) timeout of the tests' MainDevice: long enough for a
/// loaded 2-core machine running the tests in parallel (ethercrab's 10 ms EEPROM
/// default is one round trip there), short enough that the lost and late frame checks
/// take a fraction of a second.
pub const PDU_TIMEOUT: Duration = Duration::from_millis(100);
pub const PDI_LEN: usize = 256;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

pub type OpGroup = SubDeviceGroup<MAX_SUBDEVICES, PDI_LEN, DefaultLock, Op>;

/// Bytes of the default RxPDO (controlword, target torque, target position).
pub const RX_BYTES: usize = 8;
/// Bytes of the default TxPDO (statusword, position, velocity, torque, error code).
pub const TX_BYTES: usize = 14;

pub struct Bus {
    pub emulator: Emulator,
    pub maindevice: MainDevice<'static>,
    pub link: InProcessLink,
}

pub fn bus(config: &ChainConfig) -> Bus {
    let storage: &'static PduStorage<MAX_FRAMES, MAX_PDU_DATA> =
        Box::leak(Box::new(PduStorage::new()));
    let (tx, rx, pdu_loop) = storage.try_split().expect("a fresh storage splits");
    let emulator = Emulator::new(config).expect("valid chain");
    let link = InProcessLink::spawn(emulator.clone(), tx, rx).expect("link thread");
    let maindevice = MainDevice::new(
        pdu_loop,
        Timeouts {
            pdu: PDU_TIMEOUT,
            eeprom: PDU_TIMEOUT,
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 100,
            ..Default::default()
        },
    );
    Bus {
        emulator,
        maindevice,
        link,
    }
}

/// What the master read from one drive in a cycle.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    pub statusword: u16,
    pub position_counts: i32,
    pub velocity_counts_s: i32,
    pub torque_per_mille: i16,
    pub error_code: u16,
    pub step: Step,
}

fn le16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn le32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// One cycle: exchange process data, step every axis on what came back, write the
/// controlwords and target torques for the next cycle.
pub async fn cycle(
    group: &OpGroup,
    md: &MainDevice<'static>,
    axes: &mut [Axis],
    torque_per_mille: &[i16],
) -> Result<(TxRxResponse<MAX_SUBDEVICES>, Vec<Inputs>), Error> {
    let resp = group.tx_rx(md).await?;
    let mut inputs = Vec::new();
    for (i, axis) in axes.iter_mut().enumerate() {
        let sd = group.subdevice(md, i)?;
        let mut io = sd.io_raw_mut();
        let inp = io.inputs().to_vec();
        assert_eq!((inp.len(), io.outputs().len()), (TX_BYTES, RX_BYTES));
        let sw = le16(&inp, 0);
        let error_code = le16(&inp, 12);
        let state = Statusword(sw).state().expect("defined statusword");
        let step = axis.step(state, error_code);
        let out = io.outputs();
        out[0..2].copy_from_slice(&step.controlword.bits().to_le_bytes());
        out[2..4].copy_from_slice(&torque_per_mille[i].to_le_bytes());
        inputs.push(Inputs {
            statusword: sw,
            position_counts: le32(&inp, 2) as i32,
            velocity_counts_s: le32(&inp, 6) as i32,
            torque_per_mille: le16(&inp, 10) as i16,
            error_code,
            step,
        });
    }
    Ok((resp, inputs))
}
