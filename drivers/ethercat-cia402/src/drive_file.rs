//! The drive file: which EtherCAT bus, which drives, and how each maps to a robot joint.
//!
//! TOML, SI units in the key names, unknown keys refused (see
//! `drivers/ethercat-cia402/example.drive.toml`):
//!
//! ```toml
//! [bus]
//! interface = "eth1"
//! cycle_us = 1000
//! max_lost_cycles = 3
//!
//! [[axis]]
//! joint = "j1"
//! vendor_id = 0x0000009a
//! product_code = 0x00030924
//! counts_per_rev = 1048576
//! gear_ratio = 100.0          # or lead_m_per_rev for a prismatic joint
//! rated_torque_nm = 1.27      # motor side, 0x6076
//! max_torque_nm = 3.8         # motor side, enforced
//! mode = "cst"                # or "csp"
//! drive_watchdog_ms = 10
//! ```
//!
//! [`DriveFile::from_toml_str`] checks every value once and names the file and the key
//! in a refusal (`drive.toml: axis[2].gear_ratio: must be positive, got -3`); what it
//! returns is ready for the cycle, with each axis's [`AxisScaling`] precomputed.

use std::collections::HashMap;
use std::path::Path;

use serde::Deserialize;

use crate::scaling::{AxisScaling, Transmission};

/// Why a drive file could not be loaded. `origin` is the file path (or whatever the
/// caller passed to [`DriveFile::from_toml_str`]).
#[derive(Debug, thiserror::Error)]
pub enum DriveFileError {
    /// The file could not be read.
    #[error("{origin}: {source}")]
    Read {
        /// The file path.
        origin: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not valid TOML, an unknown key, a missing key or a wrong type.
    #[error("{origin}: {message}")]
    Parse {
        /// Source of the text.
        origin: String,
        /// The parser's message (names the key and the line).
        message: String,
    },
    /// A key with a bad value.
    #[error("{origin}: {key}: {message}")]
    Invalid {
        /// Source of the text.
        origin: String,
        /// The key, with the axis index: `bus.cycle_us`, `axis[2].gear_ratio`.
        key: String,
        /// What is wrong with the value.
        message: String,
    },
}

/// The CiA 402 mode of operation an axis runs in (written to 0x6060).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Cyclic synchronous position (8): the master sends target positions (0x607A).
    Csp,
    /// Cyclic synchronous torque (10): the master sends target torques (0x6071).
    Cst,
}

impl Mode {
    /// The value for modes of operation (0x6060) and its display (0x6061).
    pub const fn modes_of_operation(self) -> i8 {
        match self {
            Mode::Csp => 8,
            Mode::Cst => 10,
        }
    }
}

/// The `[bus]` table: the EtherCAT segment the drives are on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Bus {
    /// The network interface of the segment, e.g. `eth1`.
    pub interface: String,
    /// The bus cycle (µs).
    pub cycle_us: u32,
    /// Consecutive cycles without a valid process-data exchange the master rides out
    /// before it treats the bus as lost.
    pub max_lost_cycles: u32,
}

/// One `[[axis]]`: a CiA 402 drive and the joint it moves, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisConfig {
    /// The robot joint this drive moves (its name in the robot file).
    pub joint: String,
    /// The drive's EtherCAT vendor ID (identity object 0x1018:01).
    pub vendor_id: u32,
    /// The drive's product code (identity object 0x1018:02).
    pub product_code: u32,
    /// Encoder counts per motor revolution.
    pub counts_per_rev: u32,
    /// Gear ratio (revolute) or lead (prismatic).
    pub transmission: Transmission,
    /// Rated motor torque (0x6076), N·m, motor side.
    pub rated_torque_nm: f64,
    /// Torque limit, N·m, motor side: target torques are clipped to it and the drive's
    /// max torque (0x6072) is set from it.
    pub max_torque_nm: f64,
    /// Mode of operation (0x6060).
    pub mode: Mode,
    /// The drive's own communication watchdog (ms): it stops on its own when the master
    /// goes silent this long.
    pub drive_watchdog_ms: u32,
    /// Conversions between drive units and joint units, from the values above.
    pub scaling: AxisScaling,
}

/// A checked drive file: the bus and the axes in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveFile {
    /// The `[bus]` table.
    pub bus: Bus,
    /// The `[[axis]]` tables, in file order.
    pub axes: Vec<AxisConfig>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    bus: BusToml,
    #[serde(default)]
    axis: Vec<AxisToml>,
}

// Integers are read as i64 so a negative or oversized value gets a message of ours
// naming the key, rather than the parser's type error.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BusToml {
    interface: String,
    cycle_us: i64,
    max_lost_cycles: i64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisToml {
    joint: String,
    vendor_id: i64,
    product_code: i64,
    counts_per_rev: i64,
    gear_ratio: Option<f64>,
    lead_m_per_rev: Option<f64>,
    rated_torque_nm: f64,
    max_torque_nm: f64,
    mode: String,
    drive_watchdog_ms: i64,
}

/// The longest bus cycle accepted (µs).
const MAX_CYCLE_US: i64 = 1_000_000;

impl DriveFile {
    /// Reads and checks the drive file at `path`; errors name the path.
    pub fn load(path: &Path) -> Result<DriveFile, DriveFileError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| DriveFileError::Read {
            origin: origin.clone(),
            source,
        })?;
        DriveFile::from_toml_str(&text, &origin)
    }

    /// Parses and checks a drive file; `origin` names the source in errors (e.g. the
    /// file path).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<DriveFile, DriveFileError> {
        let file: FileToml = toml::from_str(text).map_err(|e| DriveFileError::Parse {
            origin: origin.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let bad = |key: String, message: String| DriveFileError::Invalid {
            origin: origin.to_string(),
            key,
            message,
        };

        let b = file.bus;
        if b.interface.trim().is_empty() {
            return Err(bad(
                "bus.interface".into(),
                "must name a network interface".into(),
            ));
        }
        if !(1..=MAX_CYCLE_US).contains(&b.cycle_us) {
            return Err(bad(
                "bus.cycle_us".into(),
                format!("must be 1..={MAX_CYCLE_US}, got {}", b.cycle_us),
            ));
        }
        let max_lost_cycles = u32::try_from(b.max_lost_cycles).map_err(|_| {
            bad(
                "bus.max_lost_cycles".into(),
                format!("must be 0..={}, got {}", u32::MAX, b.max_lost_cycles),
            )
        })?;
        let bus = Bus {
            interface: b.interface,
            // 1..=MAX_CYCLE_US fits.
            cycle_us: u32::try_from(b.cycle_us).unwrap_or(u32::MAX),
            max_lost_cycles,
        };

        if file.axis.is_empty() {
            return Err(bad("axis".into(), "at least one [[axis]] is needed".into()));
        }
        let mut joints: HashMap<String, usize> = HashMap::new();
        let mut axes = Vec::with_capacity(file.axis.len());
        for (i, a) in file.axis.into_iter().enumerate() {
            let key = |name: &str| format!("axis[{i}].{name}");
            let bad = |name: &str, message: String| bad(key(name), message);
            let u32_of = |name: &str, v: i64, min: i64| {
                if v < min || v > i64::from(u32::MAX) {
                    Err(bad(name, format!("must be {min}..={}, got {v}", u32::MAX)))
                } else {
                    Ok(u32::try_from(v).unwrap_or(u32::MAX))
                }
            };

            if a.joint.trim().is_empty() {
                return Err(bad("joint", "must name a robot joint".into()));
            }
            if let Some(first) = joints.get(&a.joint) {
                return Err(bad(
                    "joint",
                    format!("joint \"{}\" is already driven by axis[{first}]", a.joint),
                ));
            }
            joints.insert(a.joint.clone(), i);

            let vendor_id = u32_of("vendor_id", a.vendor_id, 0)?;
            let product_code = u32_of("product_code", a.product_code, 0)?;
            let counts_per_rev = if a.counts_per_rev <= 0 {
                return Err(bad(
                    "counts_per_rev",
                    format!("must be positive, got {}", a.counts_per_rev),
                ));
            } else {
                u32_of("counts_per_rev", a.counts_per_rev, 1)?
            };
            let transmission = match (a.gear_ratio, a.lead_m_per_rev) {
                (Some(gear_ratio), None) => Transmission::Revolute { gear_ratio },
                (None, Some(lead_m_per_rev)) => Transmission::Prismatic { lead_m_per_rev },
                (Some(_), Some(_)) => {
                    return Err(bad(
                        "lead_m_per_rev",
                        "give gear_ratio (revolute joint) or lead_m_per_rev (prismatic \
                         joint), not both"
                            .into(),
                    ));
                }
                (None, None) => {
                    return Err(bad(
                        "gear_ratio",
                        "missing: give gear_ratio (revolute joint) or lead_m_per_rev \
                         (prismatic joint)"
                            .into(),
                    ));
                }
            };
            let scaling = AxisScaling::new(
                counts_per_rev,
                transmission,
                a.rated_torque_nm,
                a.max_torque_nm,
            )
            .map_err(|e| bad(e.key, e.message))?;
            let mode = match a.mode.as_str() {
                "csp" => Mode::Csp,
                "cst" => Mode::Cst,
                other => {
                    return Err(bad(
                        "mode",
                        format!("must be \"csp\" or \"cst\", got \"{other}\""),
                    ));
                }
            };
            let drive_watchdog_ms = u32_of("drive_watchdog_ms", a.drive_watchdog_ms, 1)?;
            // The drive must not stop on losses the master is configured to ride out.
            let tolerated_us = (u64::from(max_lost_cycles) + 1) * u64::from(bus.cycle_us);
            if u64::from(drive_watchdog_ms) * 1000 <= tolerated_us {
                return Err(bad(
                    "drive_watchdog_ms",
                    format!(
                        "must be longer than (bus.max_lost_cycles + 1) × bus.cycle_us = {} ms, \
                         got {drive_watchdog_ms}",
                        tolerated_us as f64 / 1000.0
                    ),
                ));
            }

            axes.push(AxisConfig {
                joint: a.joint,
                vendor_id,
                product_code,
                counts_per_rev,
                transmission,
                rated_torque_nm: a.rated_torque_nm,
                max_torque_nm: a.max_torque_nm,
                mode,
                drive_watchdog_ms,
                scaling,
            });
        }
        Ok(DriveFile { bus, axes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AXIS: &str = r#"
[[axis]]
joint = "j1"
vendor_id = 0x0000009a
product_code = 0x00030924
counts_per_rev = 1048576
gear_ratio = 100.0
rated_torque_nm = 1.27
max_torque_nm = 3.8
mode = "cst"
drive_watchdog_ms = 10
"#;

    const BUS: &str = r#"
[bus]
interface = "eth1"
cycle_us = 1000
max_lost_cycles = 3
"#;

    /// A file with the bus and three axes j0, j1, j2, the axis `index` edited by
    /// `edit` (a key = value line replacing the key, or added).
    fn file_with(index: usize, key: &str, value: Option<&str>) -> String {
        let mut text = BUS.to_string();
        for i in 0..3 {
            let mut axis = AXIS.replace("\"j1\"", &format!("\"j{i}\""));
            if i == index {
                let lines: Vec<String> = axis
                    .lines()
                    .filter(|l| l.split('=').next().map(str::trim) != Some(key))
                    .map(str::to_string)
                    .collect();
                axis = lines.join("\n") + "\n";
                if let Some(v) = value {
                    axis.push_str(&format!("{key} = {v}\n"));
                }
            }
            text.push_str(&axis);
        }
        text
    }

    fn refusal(text: &str) -> String {
        match DriveFile::from_toml_str(text, "drive.toml") {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    fn refused(index: usize, key: &str, value: Option<&str>) -> String {
        refusal(&file_with(index, key, value))
    }

    #[test]
    fn the_example_file_loads() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("example.drive.toml");
        let file = DriveFile::load(&path).expect("example loads");
        assert_eq!(file.bus.interface, "eth1");
        assert_eq!(file.bus.cycle_us, 1000);
        assert_eq!(file.axes.len(), 6);
        let a = &file.axes[0];
        assert_eq!(a.vendor_id, 0x9a);
        assert_eq!(a.product_code, 0x0003_0924);
        assert_eq!(a.mode, Mode::Cst);
        assert_eq!(a.mode.modes_of_operation(), 10);
        assert_eq!(a.transmission, Transmission::Revolute { gear_ratio: 100.0 });
        // The scaling is built from the same values.
        assert_eq!(a.scaling.effort_to_target_torque(127.0).per_mille, 1000);
    }

    #[test]
    fn a_valid_file_is_taken_as_written() {
        let file = DriveFile::from_toml_str(&file_with(9, "", None), "drive.toml").expect("valid");
        assert_eq!(
            file.bus,
            Bus {
                interface: "eth1".into(),
                cycle_us: 1000,
                max_lost_cycles: 3
            }
        );
        let joints: Vec<&str> = file.axes.iter().map(|a| a.joint.as_str()).collect();
        assert_eq!(joints, ["j0", "j1", "j2"]);
        assert_eq!(file.axes[2].drive_watchdog_ms, 10);
        assert_eq!(file.axes[2].counts_per_rev, 1 << 20);
    }

    #[test]
    fn prismatic_axis_by_lead() {
        let text = file_with(1, "gear_ratio", None)
            .replace("joint = \"j1\"", "joint = \"j1\"\nlead_m_per_rev = 0.005");
        let file = DriveFile::from_toml_str(&text, "drive.toml").expect("valid");
        assert_eq!(
            file.axes[1].transmission,
            Transmission::Prismatic {
                lead_m_per_rev: 0.005
            }
        );
        assert_eq!(Mode::Csp.modes_of_operation(), 8);
    }

    #[test]
    fn bad_values_are_refused_with_file_and_key() {
        let cases: [(usize, &str, Option<&str>, &str); 17] = [
            (
                2,
                "gear_ratio",
                Some("-3"),
                "drive.toml: axis[2].gear_ratio: must be positive, got -3",
            ),
            (
                0,
                "gear_ratio",
                Some("0.0"),
                "drive.toml: axis[0].gear_ratio: must be positive, got 0",
            ),
            (
                1,
                "gear_ratio",
                Some("nan"),
                "drive.toml: axis[1].gear_ratio: must be positive, got NaN",
            ),
            (
                1,
                "counts_per_rev",
                Some("0"),
                "drive.toml: axis[1].counts_per_rev: must be positive, got 0",
            ),
            (
                1,
                "counts_per_rev",
                Some("-5"),
                "drive.toml: axis[1].counts_per_rev: must be positive, got -5",
            ),
            (
                1,
                "counts_per_rev",
                Some("4294967296"),
                "drive.toml: axis[1].counts_per_rev: must be 1..=4294967295, got 4294967296",
            ),
            (
                0,
                "vendor_id",
                Some("-1"),
                "drive.toml: axis[0].vendor_id: must be 0..=4294967295, got -1",
            ),
            (
                0,
                "product_code",
                Some("0x100000000"),
                "drive.toml: axis[0].product_code: must be 0..=4294967295, got 4294967296",
            ),
            (
                1,
                "rated_torque_nm",
                Some("0.0"),
                "drive.toml: axis[1].rated_torque_nm: must be positive, got 0",
            ),
            (
                1,
                "max_torque_nm",
                Some("-1.0"),
                "drive.toml: axis[1].max_torque_nm: must be positive, got -1",
            ),
            (
                1,
                "max_torque_nm",
                Some("1.0"),
                "drive.toml: axis[1].max_torque_nm: must be at least rated_torque_nm (1.27), got 1",
            ),
            (
                1,
                "max_torque_nm",
                Some("100.0"),
                "drive.toml: axis[1].max_torque_nm: 100 is 78740 per mille of rated_torque_nm (1.27); 0x6071 holds at most 32767",
            ),
            (
                2,
                "mode",
                Some("\"csv\""),
                "drive.toml: axis[2].mode: must be \"csp\" or \"cst\", got \"csv\"",
            ),
            (
                0,
                "drive_watchdog_ms",
                Some("0"),
                "drive.toml: axis[0].drive_watchdog_ms: must be 1..=4294967295, got 0",
            ),
            (
                0,
                "drive_watchdog_ms",
                Some("4"),
                "drive.toml: axis[0].drive_watchdog_ms: must be longer than (bus.max_lost_cycles + 1) × bus.cycle_us = 4 ms, got 4",
            ),
            (
                1,
                "joint",
                Some("\" \""),
                "drive.toml: axis[1].joint: must name a robot joint",
            ),
            (
                1,
                "gear_ratio",
                None,
                "drive.toml: axis[1].gear_ratio: missing: give gear_ratio (revolute joint) or lead_m_per_rev (prismatic joint)",
            ),
        ];
        for (index, key, value, message) in cases {
            assert_eq!(refused(index, key, value), message, "{key} = {value:?}");
        }
    }

    #[test]
    fn gear_ratio_and_lead_together_are_refused() {
        assert_eq!(
            refused(2, "lead_m_per_rev", Some("0.005")),
            "drive.toml: axis[2].lead_m_per_rev: give gear_ratio (revolute joint) or \
             lead_m_per_rev (prismatic joint), not both"
        );
        assert_eq!(
            refusal(&file_with(0, "gear_ratio", None).replacen(
                "joint = \"j0\"",
                "joint = \"j0\"\nlead_m_per_rev = -0.01",
                1
            )),
            "drive.toml: axis[0].lead_m_per_rev: must be positive, got -0.01"
        );
    }

    #[test]
    fn duplicate_joints_are_refused() {
        assert_eq!(
            refused(2, "joint", Some("\"j0\"")),
            "drive.toml: axis[2].joint: joint \"j0\" is already driven by axis[0]"
        );
    }

    #[test]
    fn bad_bus_values_are_refused() {
        let base = file_with(9, "", None);
        let cases = [
            (
                "cycle_us = 1000",
                "cycle_us = 0",
                "drive.toml: bus.cycle_us: must be 1..=1000000, got 0",
            ),
            (
                "cycle_us = 1000",
                "cycle_us = -250",
                "drive.toml: bus.cycle_us: must be 1..=1000000, got -250",
            ),
            (
                "max_lost_cycles = 3",
                "max_lost_cycles = -1",
                "drive.toml: bus.max_lost_cycles: must be 0..=4294967295, got -1",
            ),
            (
                "interface = \"eth1\"",
                "interface = \"\"",
                "drive.toml: bus.interface: must name a network interface",
            ),
            // The watchdog check follows the bus: 10 ms is not above 10 × 1 ms.
            (
                "max_lost_cycles = 3",
                "max_lost_cycles = 9",
                "drive.toml: axis[0].drive_watchdog_ms: must be longer than (bus.max_lost_cycles + 1) × bus.cycle_us = 10 ms, got 10",
            ),
        ];
        for (from, to, message) in cases {
            assert_eq!(refusal(&base.replacen(from, to, 1)), message, "{to}");
        }
        assert_eq!(
            refusal(BUS),
            "drive.toml: axis: at least one [[axis]] is needed"
        );
    }

    #[test]
    fn unknown_missing_and_mistyped_keys_are_refused_by_the_parser() {
        for (text, needle) in [
            (file_with(1, "gear_ratio_x", Some("3.0")), "gear_ratio_x"),
            (BUS.replace("cycle_us", "cycle_ms") + AXIS, "cycle_ms"),
            (file_with(1, "rated_torque_nm", None), "rated_torque_nm"),
            (
                file_with(1, "counts_per_rev", Some("\"many\"")),
                "counts_per_rev",
            ),
            (AXIS.to_string(), "bus"),
            (format!("{BUS}{AXIS}[extra]\n"), "extra"),
        ] {
            let message = refusal(&text);
            assert!(message.starts_with("drive.toml: "), "{message}");
            assert!(message.contains(needle), "{needle} not in: {message}");
        }
    }

    #[test]
    fn an_unreadable_file_is_refused_with_its_path() {
        let e = DriveFile::load(Path::new("/nonexistent/drive.toml")).expect_err("no file");
        assert!(
            e.to_string().starts_with("/nonexistent/drive.toml: "),
            "{e}"
        );
    }
}
