//! The transport-free core of an EtherCAT CiA 402 (IEC 61800-7-201) servo-drive driver.
//!
//! - [`cia402`]: the power drive state machine — statusword (0x6041) decoding,
//!   controlword (0x6040) commands, and a per-axis [`cia402::Axis`] that walks a drive to
//!   the wanted state one transition per cycle, resets faults only when asked and
//!   reports transitions the standard does not allow.
//! - [`scaling`]: per-axis conversions between drive units (encoder counts, per mille of
//!   rated torque 0x6076) and joint SI units (rad or m, N·m or N), precomputed once.
//! - [`drive_file`]: the TOML drive file (bus and axes), checked key by key.
//!
//! Nothing here touches the bus: the EtherCAT master uses these modules to fill and read
//! the process data. The only I/O is reading the drive file.

pub mod cia402;
pub mod drive_file;
pub mod scaling;
