//! An emulated EtherCAT chain of CiA 402 servo drives that stands in for hardware.
//!
//! An unchanged ethercrab `MainDevice` discovers the chain, reads the drives' SII
//! EEPROM, talks CoE SDO over their mailboxes, brings them to OP and exchanges cyclic
//! process data through their FMMUs; each drive runs the CiA 402 power state machine
//! and moves a plant (the seed arm's dynamics, or independent inertias). Faults are
//! injected on command.
//!
//! - [`Emulator`]: the chain (build it from a [`ChainConfig`]); [`Emulator::handle_frame`]
//!   answers one Ethernet frame, [`Emulator::inject`] injects a [`Fault`],
//!   [`Emulator::drive`] shows a drive.
//! - [`InProcessLink`]: answers ethercrab's `PduTx`/`PduRx` halves on a thread, no socket.
//! - [`raw_socket`]: an AF_PACKET socket on an interface (one end of a veth pair).
//! - [`plant`]: the [`Plant`] trait and the two plants.
//!
//! See the crate README for what is emulated and what is not.
//!
//! ```
//! use std::time::Duration;
//!
//! use ethercrab::{MainDevice, MainDeviceConfig, PduStorage, Timeouts, std::ethercat_now};
//! use microrobot_ethercat_emulator::{ChainConfig, Emulator, Fault, InProcessLink, MODE_CST};
//!
//! static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();
//! let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
//! let emulator = Emulator::new(&ChainConfig::inertia_chain(2))?;
//! let _link = InProcessLink::spawn(emulator.clone(), tx, rx)?; // answers until dropped
//! // On a loaded test machine one round trip can exceed ethercrab's 10 ms EEPROM wait.
//! let timeouts = Timeouts { eeprom: Duration::from_millis(100), ..Timeouts::default() };
//! let md = MainDevice::new(pdu_loop, timeouts, MainDeviceConfig::default());
//! async_io::block_on(async {
//!     let group = md.init_single_group::<8, 64>(ethercat_now).await?;
//!     for sd in group.iter(&md) {
//!         sd.sdo_write(0x6060, 0, MODE_CST).await?; // cyclic synchronous torque
//!     }
//!     let group = group.into_op(&md).await?;
//!     assert_eq!(group.tx_rx(&md).await?.working_counter, 6); // 3 per drive
//!     Ok::<(), ethercrab::error::Error>(())
//! })?;
//! emulator.inject(Fault::DriveFault { drive: 1, error_code: 0x2310 })?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod config;
pub mod fault;
pub mod plant;
pub mod raw_socket;

mod coe;
mod drive;
mod emulator;
mod esc;
mod in_process;
mod od;
mod sii;

pub use config::{ChainConfig, ConfigError, DriveConfig, Identity, PlantKind, TimeMode};
pub use drive::{ERROR_COMMUNICATION, MODE_CSP, MODE_CST};
pub use emulator::{Counters, DriveSnapshot, ETHERCAT_ETHERTYPE, Emulator, NoSuchDrive, Reply};
pub use esc::al_status_code;
pub use fault::Fault;
pub use in_process::InProcessLink;
pub use od::abort as sdo_abort;
pub use plant::Plant;

/// AL states as in AL status 0x0130 bits 0-3 (ETG.1000.6 6.4.1).
pub mod al_state {
    /// INIT.
    pub const INIT: u8 = 1;
    /// PRE-OP.
    pub const PRE_OP: u8 = 2;
    /// SAFE-OP.
    pub const SAFE_OP: u8 = 4;
    /// OP.
    pub const OP: u8 = 8;
}
