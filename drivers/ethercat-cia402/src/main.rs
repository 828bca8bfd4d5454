//! `microrobot-ethercat-cia402`: the pipeline's actuator on an EtherCAT bus of CiA 402
//! servo drives, on the driver SDK.
//!
//! ```text
//! microrobot-ethercat-cia402 --drive-file FILE [--interface IFACE] [--config FILE] [--instance NAME] [--rate-hz HZ]
//! ```
//! `--drive-file`: the drive file (see `example.drive.toml`); `--interface`: the network
//! interface, instead of the file's `bus.interface`. The bus cycle must match the
//! pipeline's rate. Opening the interface needs CAP_NET_RAW.

use std::path::Path;
use std::process::ExitCode;

use microrobot_driver::Args;
use microrobot_driver::anyhow::{self, Context};
use microrobot_ethercat_cia402::backend::EthercatBackend;
use microrobot_ethercat_cia402::drive_file::DriveFile;
use microrobot_ethercat_cia402::master::Transport;
use microrobot_ethercat_cia402::raw_socket::TransportRt;

const NAME: &str = "microrobot-ethercat-cia402";

/// The drive file with `--interface` applied, checked before the pipeline config.
fn drive_file(args: &Args) -> Result<DriveFile, String> {
    let path = args
        .value("--drive-file")
        .ok_or("--drive-file FILE is required (the drives on the bus, see example.drive.toml)")?;
    let mut file = DriveFile::load(Path::new(path)).map_err(|e| e.to_string())?;
    if let Some(iface) = args.value("--interface") {
        if iface.trim().is_empty() {
            return Err("--interface must name a network interface".into());
        }
        file.bus.interface = iface.to_string();
    }
    Ok(file)
}

fn main() -> ExitCode {
    // Before the service installs tracing: ethercrab's line per late frame stays out of
    // the log, the backend reports lost exchanges itself.
    microrobot_runtime::init_tracing_quiet(microrobot_ethercat_cia402::report::QUIET);
    let parsed =
        Args::from_env(&["--drive-file", "--interface"]).and_then(|a| Ok((drive_file(&a)?, a)));
    let (file, args) = match parsed {
        Ok(p) => p,
        Err(e) => return microrobot_driver::usage_error(NAME, &e),
    };
    microrobot_driver::main(&args, move |s| {
        let cycle_s = f64::from(file.bus.cycle_us) * 1e-6;
        anyhow::ensure!(
            (cycle_s * s.rate_hz() - 1.0).abs() < 1e-6,
            "the drive file's bus.cycle_us {} µs does not match the pipeline's rate {} Hz ({} µs)",
            file.bus.cycle_us,
            s.rate_hz(),
            1e6 / s.rate_hz()
        );
        let names: Vec<&str> = s.robot.joints().iter().map(|j| j.name.as_str()).collect();
        let iface = file.bus.interface.clone();
        // The transport thread runs with the cycle's real-time settings (one step above).
        let rt = TransportRt(s.cfg.service_realtime());
        let connect = Box::new(move || Transport::raw_socket(&iface, Some(rt.clone())));
        EthercatBackend::new(file, &names, connect)
            .map_err(anyhow::Error::msg)
            .context("drive file")
    })
}
