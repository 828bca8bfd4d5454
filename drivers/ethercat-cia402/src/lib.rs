//! An EtherCAT driver for CiA 402 (IEC 61800-7-201) servo drives.
//!
//! The transport-free core:
//!
//! - [`cia402`]: the power drive state machine — statusword (0x6041) decoding,
//!   controlword (0x6040) commands, and a per-axis [`cia402::Axis`] that walks a drive to
//!   the wanted state one transition per cycle, resets faults only when asked and
//!   reports transitions the standard does not allow.
//! - [`scaling`]: per-axis conversions between drive units (encoder counts, per mille of
//!   rated torque 0x6076) and joint SI units (rad or m, N·m or N), precomputed once.
//! - [`drive_file`]: the TOML drive file (bus and axes), checked key by key.
//! - [`dc`]: the SyncManager parameter objects 0x1C32/0x1C33 (sync mode, cycle time)
//!   and the phase of the exchange against SYNC0.
//! - [`pdo`]: the process data image (RxPDO 0x1600, TxPDO 0x1A00) and the PRE-OP SDO
//!   configuration, as data.
//!
//! On the bus, with [ethercrab](https://docs.rs/ethercrab):
//!
//! - [`master`]: the bus brought up from the drive file (identities checked first, SDO
//!   configuration, watchdog, distributed clocks, OP) and the bounded cyclic exchange.
//! - [`raw_socket`]: the AF_PACKET transport of the binary.
//! - [`report`]: the driver's own rate-limited report of lost exchanges, and the
//!   per-late-frame line of ethercrab's it leaves out of the log.
//! - [`backend`]: the pipeline's actuator backend over it; the binary
//!   `microrobot-ethercat-cia402` hands it to the driver SDK.

pub mod backend;
pub mod cia402;
pub mod dc;
pub mod drive_file;
pub mod master;
pub mod pdo;
pub mod raw_socket;
pub mod report;
pub mod scaling;
