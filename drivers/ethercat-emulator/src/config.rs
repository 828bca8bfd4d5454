//! The chain's configuration: the drives in bus order, their identities and scaling,
//! the plant, and how simulated time advances. Read from a small TOML file or built in
//! code; every value is checked with the key named.

use serde::Deserialize;
use std::path::Path;

/// Vendor id of the seed arm's drives (the same as in the driver's example drive file).
pub const SEED_VENDOR_ID: u32 = 0x0000_009A;
/// Product code of the seed arm's drives (the same as in the driver's example drive file).
pub const SEED_PRODUCT_CODE: u32 = 0x0003_0924;
/// Default minimum cycle time of a drive (ns), 0x1C32:05: 125 µs (8 kHz).
pub const DEFAULT_MIN_CYCLE_TIME_NS: u32 = 125_000;
/// Default calc-and-copy time of a drive (ns), 0x1C32:06.
pub const DEFAULT_CALC_COPY_TIME_NS: u32 = 20_000;

/// A configuration value out of range or a file that cannot be read; `key` names the
/// value as in the TOML file (`drive[2].gear_ratio`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{origin}: {}{message}", if key == "-" { String::new() } else { format!("{key}: ") })]
pub struct ConfigError {
    /// The file (or `"<built-in>"`).
    pub origin: String,
    /// The key of the bad value, or `"-"` for the file as a whole.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

/// The identity a drive reports in its SII EEPROM (words 0x0008-0x000F, ETG.2010
/// table 2) and in object 0x1018.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Vendor id (ETG-assigned), 0x1018:01.
    pub vendor_id: u32,
    /// Product code, 0x1018:02.
    pub product_code: u32,
    /// Revision number, 0x1018:03.
    pub revision: u32,
    /// Serial number, 0x1018:04.
    pub serial: u32,
}

/// One emulated drive (one EtherCAT SubDevice with one CiA 402 axis).
#[derive(Debug, Clone, PartialEq)]
pub struct DriveConfig {
    /// Device name, in the SII strings (what ethercrab's `SubDevice::name` returns) and
    /// object 0x1008. At most 64 ASCII characters.
    pub name: String,
    /// Identity in the SII and object 0x1018.
    pub identity: Identity,
    /// Motor encoder resolution (counts per motor revolution): 0x6064, 0x606C, 0x607A.
    pub encoder_counts_per_rev: u32,
    /// Motor revolutions per joint revolution (positive).
    pub gear_ratio: f64,
    /// Rated motor torque (N·m), object 0x6076; 0x6071 and 0x6077 are per mille of it.
    pub rated_torque_nm: f64,
    /// Max torque (per mille of rated), object 0x6072 at power on.
    pub max_torque_per_mille: u16,
    /// Position loop gain of the drive in CSP mode (joint N·m per rad).
    pub csp_kp_nm_per_rad: f64,
    /// Velocity damping of the drive in CSP mode (joint N·m per rad/s).
    pub csp_kd_nm_s_per_rad: f64,
    /// Shortest cycle the drive runs synchronised (ns), 0x1C32:05 / 0x1C33:05.
    pub min_cycle_time_ns: u32,
    /// Time the drive needs from the SYNC0 event to its outputs applied (ns),
    /// 0x1C32:06 / 0x1C33:06.
    pub calc_copy_time_ns: u32,
}

/// Which plant the chain's motors drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantKind {
    /// The seed arm's forward dynamics (`microrobot-model`, config/robots/seed-arm.toml);
    /// needs exactly 6 drives.
    SeedArm,
    /// Independent axes, each a pure inertia ([`crate::plant::InertiaPlant`]).
    Inertia {
        /// Joint-side inertia of every axis (kg·m²).
        inertia_kg_m2: f64,
    },
}

/// How simulated time advances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeMode {
    /// Each process data exchange (a logical datagram reaching the drives) advances the
    /// plant by this many seconds: deterministic, for tests.
    PerExchange {
        /// Simulated time per exchange (s).
        cycle_s: f64,
    },
    /// The plant advances by the wall-clock time between exchanges, at most
    /// `max_step_s` per exchange (a paused master does not make the arm jump).
    WallClock {
        /// Upper bound of one step (s).
        max_step_s: f64,
    },
}

/// The whole emulated chain, drives in bus order (position 0 next to the master).
#[derive(Debug, Clone, PartialEq)]
pub struct ChainConfig {
    /// The drives, in bus order.
    pub drives: Vec<DriveConfig>,
    /// The plant behind the motors.
    pub plant: PlantKind,
    /// How simulated time advances.
    pub time: TimeMode,
    /// Rate error of the drives' clocks (DC, watchdog) against the host's monotonic
    /// clock (ppm; positive: the drives' clocks run fast). On hardware the DC reference
    /// clock's crystal drifts this way; 0 by default.
    pub dc_drift_ppm: f64,
}

impl DriveConfig {
    /// A drive of the seed arm's kind for axis `axis` (0-based): the scaling of the
    /// driver's example drive file (20-bit encoder; gear 100 and 1.27 N·m rated on axes
    /// 1-3, gear 50 and 0.64 N·m on axes 4-6).
    pub fn seed_axis(axis: usize) -> DriveConfig {
        let (gear_ratio, rated_torque_nm) = if axis < 3 {
            (100.0, 1.27)
        } else {
            (50.0, 0.64)
        };
        DriveConfig {
            name: format!("MR-SERVO-J{}", axis + 1),
            identity: Identity {
                vendor_id: SEED_VENDOR_ID,
                product_code: SEED_PRODUCT_CODE,
                revision: 0x0001_0000,
                serial: 0x1000 + axis as u32,
            },
            encoder_counts_per_rev: 1 << 20,
            gear_ratio,
            rated_torque_nm,
            max_torque_per_mille: 3000,
            csp_kp_nm_per_rad: 2000.0,
            csp_kd_nm_s_per_rad: 60.0,
            min_cycle_time_ns: DEFAULT_MIN_CYCLE_TIME_NS,
            calc_copy_time_ns: DEFAULT_CALC_COPY_TIME_NS,
        }
    }
}

impl ChainConfig {
    /// The seed arm: six drives ([`DriveConfig::seed_axis`]) on the seed arm's dynamics,
    /// 1 ms of simulated time per exchange.
    pub fn seed_arm() -> ChainConfig {
        ChainConfig {
            drives: (0..6).map(DriveConfig::seed_axis).collect(),
            plant: PlantKind::SeedArm,
            time: TimeMode::PerExchange { cycle_s: 0.001 },
            dc_drift_ppm: 0.0,
        }
    }

    /// `n` seed-kind drives on independent inertias of 0.05 kg·m², 1 ms per exchange.
    pub fn inertia_chain(n: usize) -> ChainConfig {
        ChainConfig {
            drives: (0..n).map(DriveConfig::seed_axis).collect(),
            plant: PlantKind::Inertia {
                inertia_kg_m2: 0.05,
            },
            time: TimeMode::PerExchange { cycle_s: 0.001 },
            dc_drift_ppm: 0.0,
        }
    }

    /// Checks every value; the error names the first bad key.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let err = |key: String, message: String| ConfigError {
            origin: origin.to_string(),
            key,
            message,
        };
        if self.drives.is_empty() {
            return Err(err("drive".into(), "at least one drive is needed".into()));
        }
        if self.drives.len() > 64 {
            return Err(err(
                "drive".into(),
                format!("at most 64 drives, got {}", self.drives.len()),
            ));
        }
        for (i, d) in self.drives.iter().enumerate() {
            let k = |name: &str| format!("drive[{i}].{name}");
            if d.name.is_empty() || d.name.len() > 64 || !d.name.is_ascii() {
                return Err(err(k("name"), "must be 1 to 64 ASCII characters".into()));
            }
            if d.encoder_counts_per_rev == 0 {
                return Err(err(k("encoder_counts_per_rev"), "must be positive".into()));
            }
            if !(d.gear_ratio.is_finite() && d.gear_ratio > 0.0) {
                return Err(err(
                    k("gear_ratio"),
                    format!("must be positive, got {}", d.gear_ratio),
                ));
            }
            if !(d.rated_torque_nm.is_finite() && d.rated_torque_nm > 0.0) {
                return Err(err(
                    k("rated_torque_nm"),
                    format!("must be positive, got {}", d.rated_torque_nm),
                ));
            }
            for (key, v) in [
                ("csp_kp_nm_per_rad", d.csp_kp_nm_per_rad),
                ("csp_kd_nm_s_per_rad", d.csp_kd_nm_s_per_rad),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(err(k(key), format!("must be zero or positive, got {v}")));
                }
            }
            if d.min_cycle_time_ns == 0 {
                return Err(err(k("min_cycle_time_ns"), "must be positive".into()));
            }
        }
        if !(self.dc_drift_ppm.is_finite() && self.dc_drift_ppm.abs() <= 1000.0) {
            return Err(err(
                "dc_drift_ppm".into(),
                format!("must be within ±1000 ppm, got {}", self.dc_drift_ppm),
            ));
        }
        match self.plant {
            PlantKind::SeedArm if self.drives.len() != 6 => {
                return Err(err(
                    "plant".into(),
                    format!(
                        "\"seed_arm\" has 6 joints, the chain has {} drives",
                        self.drives.len()
                    ),
                ));
            }
            PlantKind::Inertia { inertia_kg_m2 }
                if !(inertia_kg_m2 > 0.0 && inertia_kg_m2.is_finite()) =>
            {
                return Err(err(
                    "inertia_kg_m2".into(),
                    format!("must be positive, got {inertia_kg_m2}"),
                ));
            }
            _ => {}
        }
        match self.time {
            TimeMode::PerExchange { cycle_s } if !(cycle_s > 0.0 && cycle_s <= 1.0) => Err(err(
                "cycle_s".into(),
                format!("must be in (0, 1] s, got {cycle_s}"),
            )),
            TimeMode::WallClock { max_step_s } if !(max_step_s > 0.0 && max_step_s <= 1.0) => {
                Err(err(
                    "max_step_s".into(),
                    format!("must be in (0, 1] s, got {max_step_s}"),
                ))
            }
            _ => Ok(()),
        }
    }

    /// Parses the TOML chain file (see the crate README for the keys); `origin` names
    /// the file in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<ChainConfig, ConfigError> {
        let file: ChainFile = toml::from_str(text).map_err(|e| ConfigError {
            origin: origin.to_string(),
            key: "-".into(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let config = file.into_config(origin)?;
        config.validate(origin)?;
        Ok(config)
    }

    /// Reads and parses a TOML chain file.
    pub fn from_file(path: &Path) -> Result<ChainConfig, ConfigError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            origin: origin.clone(),
            key: "-".into(),
            message: format!("cannot read: {e}"),
        })?;
        ChainConfig::from_toml_str(&text, &origin)
    }
}

/// The TOML file's shape.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ChainFile {
    /// "seed_arm" or "inertia".
    #[serde(default = "default_plant")]
    plant: String,
    inertia_kg_m2: Option<f64>,
    /// Fixed simulated time per exchange; absent means wall clock.
    cycle_s: Option<f64>,
    max_step_s: Option<f64>,
    /// A chain of `drives` seed-kind drives, when no `[[drive]]` is given.
    drives: Option<usize>,
    #[serde(default)]
    dc_drift_ppm: f64,
    #[serde(default)]
    drive: Vec<DriveFile>,
}

fn default_plant() -> String {
    "inertia".into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DriveFile {
    name: Option<String>,
    vendor_id: Option<u32>,
    product_code: Option<u32>,
    revision: Option<u32>,
    serial: Option<u32>,
    encoder_counts_per_rev: Option<u32>,
    gear_ratio: Option<f64>,
    rated_torque_nm: Option<f64>,
    max_torque_per_mille: Option<u16>,
    csp_kp_nm_per_rad: Option<f64>,
    csp_kd_nm_s_per_rad: Option<f64>,
    min_cycle_time_ns: Option<u32>,
    calc_copy_time_ns: Option<u32>,
}

impl ChainFile {
    fn into_config(self, origin: &str) -> Result<ChainConfig, ConfigError> {
        let err = |key: &str, message: String| ConfigError {
            origin: origin.to_string(),
            key: key.to_string(),
            message,
        };
        let drives: Vec<DriveConfig> = match (self.drives, self.drive.is_empty()) {
            (Some(_), false) => {
                return Err(err(
                    "drives",
                    "give either `drives = N` or [[drive]] tables, not both".into(),
                ));
            }
            (Some(n), true) => (0..n).map(DriveConfig::seed_axis).collect(),
            (None, _) => self
                .drive
                .into_iter()
                .enumerate()
                .map(|(i, d)| {
                    let s = DriveConfig::seed_axis(i);
                    DriveConfig {
                        name: d.name.unwrap_or(s.name),
                        identity: Identity {
                            vendor_id: d.vendor_id.unwrap_or(s.identity.vendor_id),
                            product_code: d.product_code.unwrap_or(s.identity.product_code),
                            revision: d.revision.unwrap_or(s.identity.revision),
                            serial: d.serial.unwrap_or(s.identity.serial),
                        },
                        encoder_counts_per_rev: d
                            .encoder_counts_per_rev
                            .unwrap_or(s.encoder_counts_per_rev),
                        gear_ratio: d.gear_ratio.unwrap_or(s.gear_ratio),
                        rated_torque_nm: d.rated_torque_nm.unwrap_or(s.rated_torque_nm),
                        max_torque_per_mille: d
                            .max_torque_per_mille
                            .unwrap_or(s.max_torque_per_mille),
                        csp_kp_nm_per_rad: d.csp_kp_nm_per_rad.unwrap_or(s.csp_kp_nm_per_rad),
                        csp_kd_nm_s_per_rad: d.csp_kd_nm_s_per_rad.unwrap_or(s.csp_kd_nm_s_per_rad),
                        min_cycle_time_ns: d.min_cycle_time_ns.unwrap_or(s.min_cycle_time_ns),
                        calc_copy_time_ns: d.calc_copy_time_ns.unwrap_or(s.calc_copy_time_ns),
                    }
                })
                .collect(),
        };
        let plant = match self.plant.as_str() {
            "seed_arm" => {
                if self.inertia_kg_m2.is_some() {
                    return Err(err("inertia_kg_m2", "only for plant = \"inertia\"".into()));
                }
                PlantKind::SeedArm
            }
            "inertia" => PlantKind::Inertia {
                inertia_kg_m2: self.inertia_kg_m2.unwrap_or(0.05),
            },
            other => {
                return Err(err(
                    "plant",
                    format!("\"{other}\" is not a plant; use \"seed_arm\" or \"inertia\""),
                ));
            }
        };
        let time = match (self.cycle_s, self.max_step_s) {
            (Some(_), Some(_)) => {
                return Err(err(
                    "cycle_s",
                    "give either cycle_s (fixed step) or max_step_s (wall clock)".into(),
                ));
            }
            (Some(cycle_s), None) => TimeMode::PerExchange { cycle_s },
            (None, max) => TimeMode::WallClock {
                max_step_s: max.unwrap_or(0.01),
            },
        };
        Ok(ChainConfig {
            drives,
            plant,
            time,
            dc_drift_ppm: self.dc_drift_ppm,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_with_drive_tables_parses_and_defaults_fill_in() {
        let c = ChainConfig::from_toml_str(
            "plant = \"inertia\"\ncycle_s = 0.002\n[[drive]]\nname = \"A\"\nvendor_id = 0x42\n[[drive]]\ngear_ratio = 10.0\n",
            "t.toml",
        )
        .expect("valid");
        assert_eq!(c.drives.len(), 2);
        assert_eq!(c.drives[0].identity.vendor_id, 0x42);
        assert_eq!(c.drives[1].gear_ratio, 10.0);
        assert_eq!(c.time, TimeMode::PerExchange { cycle_s: 0.002 });
        assert_eq!(c.dc_drift_ppm, 0.0);
        assert_eq!(c.drives[0].min_cycle_time_ns, DEFAULT_MIN_CYCLE_TIME_NS);
        let c = ChainConfig::from_toml_str(
            "dc_drift_ppm = -40.0\n[[drive]]\nmin_cycle_time_ns = 250000\ncalc_copy_time_ns = 5000\n",
            "t.toml",
        )
        .expect("valid");
        assert_eq!(c.dc_drift_ppm, -40.0);
        assert_eq!(
            (c.drives[0].min_cycle_time_ns, c.drives[0].calc_copy_time_ns),
            (250_000, 5_000)
        );
    }

    #[test]
    fn the_example_file_is_the_seed_arm_on_the_wall_clock() {
        let c =
            ChainConfig::from_toml_str(include_str!("../example.chain.toml"), "example.chain.toml")
                .expect("valid example");
        let mut seed = ChainConfig::seed_arm();
        seed.time = TimeMode::WallClock { max_step_s: 0.01 };
        assert_eq!(c, seed);
    }

    #[test]
    fn bad_values_name_their_key() {
        let e = ChainConfig::from_toml_str("[[drive]]\ngear_ratio = -3.0\n", "t.toml")
            .expect_err("negative gear");
        assert_eq!(e.key, "drive[0].gear_ratio");
        let e = ChainConfig::from_toml_str("drives = 5\nplant = \"seed_arm\"\n", "t.toml")
            .expect_err("seed arm needs 6");
        assert_eq!(e.key, "plant");
        let e = ChainConfig::from_toml_str("drivez = 5\n", "t.toml").expect_err("unknown key");
        assert!(e.message.contains("drivez"), "{e}");
        let e = ChainConfig::from_toml_str("drives = 0\n", "t.toml").expect_err("empty");
        assert_eq!(e.key, "drive");
        let e = ChainConfig::from_toml_str("drives = 1\ndc_drift_ppm = 5000.0\n", "t.toml")
            .expect_err("drift");
        assert_eq!(e.key, "dc_drift_ppm");
        let e = ChainConfig::from_toml_str("[[drive]]\nmin_cycle_time_ns = 0\n", "t.toml")
            .expect_err("zero minimum cycle");
        assert_eq!(e.key, "drive[0].min_cycle_time_ns");
    }
}
