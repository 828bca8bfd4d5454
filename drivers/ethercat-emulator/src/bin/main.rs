//! `microrobot-ethercat-emulator`: an emulated CiA 402 drive chain answering EtherCAT
//! frames on a network interface (one end of a veth pair), with fault injection by
//! commands on standard input (one per line; see the crate README).

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::Parser;
use microrobot_ethercat_emulator::{ChainConfig, Emulator, Fault, PlantKind, TimeMode, raw_socket};

/// Emulated EtherCAT CiA 402 drive chain on a raw socket.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Network interface to answer on (e.g. one end of a veth pair).
    #[arg(long, short)]
    interface: String,
    /// TOML chain file (drives, identities, encoder resolution, plant, time).
    #[arg(long, short, conflicts_with_all = ["drives", "seed_arm"])]
    config: Option<PathBuf>,
    /// A chain of N seed-kind drives on independent inertias (without --config).
    #[arg(long, short, value_parser = clap::value_parser!(u16).range(1..=64))]
    drives: Option<u16>,
    /// The six-drive seed arm on its dynamics (without --config).
    #[arg(long, conflicts_with = "drives")]
    seed_arm: bool,
    /// Fixed simulated time per exchange in seconds, instead of the wall clock.
    #[arg(long)]
    cycle_s: Option<f64>,
}

fn main() -> std::process::ExitCode {
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let mut config = if let Some(path) = &args.config {
        ChainConfig::from_file(path)?
    } else if args.seed_arm {
        ChainConfig::seed_arm()
    } else {
        ChainConfig::inertia_chain(usize::from(args.drives.unwrap_or(6)))
    };
    if args.config.is_none() {
        config.time = TimeMode::WallClock { max_step_s: 0.01 };
    }
    if let Some(cycle_s) = args.cycle_s {
        config.time = TimeMode::PerExchange { cycle_s };
    }
    let emulator = Emulator::new(&config)?;
    let socket = raw_socket::RawSocket::bind(&args.interface).with_context(|| {
        format!(
            "cannot open a raw socket on {} (needs CAP_NET_RAW and the interface up)",
            args.interface
        )
    })?;
    let plant = match config.plant {
        PlantKind::SeedArm => "seed arm",
        PlantKind::Inertia { .. } => "inertia",
    };
    println!(
        "ready: {} drives ({plant}) on {}",
        config.drives.len(),
        args.interface
    );
    let stop = Arc::new(AtomicBool::new(false));
    let control = emulator.clone();
    std::thread::Builder::new()
        .name("control".into())
        .spawn(move || control_loop(&control))?;
    raw_socket::serve(&emulator, &socket, &stop)?;
    stop.store(true, Ordering::Release);
    Ok(())
}

/// Reads commands from standard input until it closes; answers each line with `ok`
/// or `error: …` (and `status` with one line per drive).
fn control_loop(emulator: &Emulator) {
    let stdin = std::io::stdin();
    for line in stdin.lock().lines() {
        let Ok(line) = line else { break };
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if line == "status" {
            for i in 0..emulator.len() {
                if let Some(d) = emulator.drive(i) {
                    println!(
                        "drive {i}: {} statusword 0x{:04X} error 0x{:04X} al 0x{:02X}{} code 0x{:04X} q {:.6} rad torque {:.3} N·m",
                        d.state,
                        d.statusword,
                        d.error_code,
                        d.al_state,
                        if d.al_error { "+err" } else { "" },
                        d.al_status_code,
                        d.position_rad,
                        d.torque_nm
                    );
                }
            }
            let c = emulator.counters();
            println!(
                "frames: answered {} malformed {} dropped {} ignored {} exchanges {}",
                c.answered, c.malformed, c.dropped_by_fault, c.ignored, c.exchanges
            );
            println!("ok");
            continue;
        }
        match line.parse::<Fault>() {
            Ok(fault) => match emulator.inject(fault) {
                Ok(()) => println!("ok"),
                Err(e) => println!("error: {e}"),
            },
            Err(e) => println!("error: {e}"),
        }
    }
}
