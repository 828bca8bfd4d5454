//! The rig the EtherCAT system tests share: a network namespace of the calling test
//! thread's own (it vanishes with the thread; the processes the thread starts inherit
//! it) with a veth pair, the emulated six-drive seed arm (`microrobot-ethercat-emulator
//! --seed-arm`) answering on one end with its fault injection channel on its standard
//! input, and the drive file and pipeline config that run the driver
//! (`microrobot-ethercat-cia402`) on the other end.
//!
//! Needs CAP_NET_ADMIN (namespace, veth) and CAP_NET_RAW (AF_PACKET). Without them
//! [`Rig::start`] prints why and returns `None` (the test passes), unless
//! MICROROBOT_REQUIRE_NETNS=1, where it fails.

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

use crate::common::*;

/// The driver's end of the veth pair.
pub const MASTER_IF: &str = "ecm0";
/// The emulated chain's end.
pub const CHAIN_IF: &str = "ecm1";

fn not_permitted(why: &str) {
    let need = format!(
        "netns system test: needs CAP_NET_ADMIN and CAP_NET_RAW (network namespace, veth pair, AF_PACKET): {why}"
    );
    if std::env::var("MICROROBOT_REQUIRE_NETNS").as_deref() == Ok("1") {
        panic!("FAILED {need} (MICROROBOT_REQUIRE_NETNS=1)");
    }
    println!("SKIPPED {need}");
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// The calling thread in a network namespace of its own with the veth pair up;
/// false (after saying why) if not permitted.
fn private_netns_with_veth() -> bool {
    // SAFETY: unshare(2) changes only this thread's network namespace; the processes
    // started from this thread inherit it.
    if unsafe { libc::unshare(libc::CLONE_NEWNET) } != 0 {
        not_permitted(&format!(
            "unshare(CLONE_NEWNET): {}",
            std::io::Error::last_os_error()
        ));
        return false;
    }
    let setup = ip(&["link", "set", "lo", "up"])
        .and_then(|()| {
            ip(&[
                "link", "add", MASTER_IF, "type", "veth", "peer", "name", CHAIN_IF,
            ])
        })
        .and_then(|()| ip(&["link", "set", MASTER_IF, "up"]))
        .and_then(|()| ip(&["link", "set", CHAIN_IF, "up"]));
    if let Err(e) = setup {
        not_permitted(&e);
        return false;
    }
    true
}

/// The driver binary of this build.
pub fn driver_binary() -> PathBuf {
    workspace_binary(
        "microrobot-ethercat-cia402",
        "microrobot-ethercat-cia402",
        &["drivers/microrobot-driver", "drivers/ethercat-cia402"],
    )
}

/// How the rig runs.
#[derive(Debug, Clone, Copy)]
pub struct RigOptions {
    /// The bus cycle and pipeline period (µs).
    pub cycle_us: u32,
    /// The emulator's time advances one bus cycle per exchange (for lockstep runs);
    /// otherwise it follows the wall clock.
    pub time_per_exchange: bool,
    /// The drive file's `max_lost_cycles`.
    pub max_lost_cycles: u32,
    /// The drive file's `drive_watchdog_ms` (every axis).
    pub drive_watchdog_ms: u32,
}

impl RigOptions {
    /// Lockstep at 250 Hz (bus cycle 4 ms; the exchange deadline, half a cycle, leaves
    /// room on a loaded machine). A shared, loaded test machine deschedules the emulator
    /// and the socket thread for tens of ms at times: 100 ms of lost exchanges are
    /// ridden out, and the drives' watchdog (wall clock) is 1 s, longer than a start-up
    /// gap between the bus reaching OP and the first torque.
    pub fn lockstep() -> Self {
        Self {
            cycle_us: 4000,
            time_per_exchange: true,
            max_lost_cycles: 25,
            drive_watchdog_ms: 1000,
        }
    }

    /// Free-running at `cycle_us` on the wall clock, as on hardware.
    pub fn free_running(cycle_us: u32) -> Self {
        Self {
            cycle_us,
            time_per_exchange: false,
            max_lost_cycles: 100_000 / cycle_us,
            drive_watchdog_ms: 1000,
        }
    }

    /// The pipeline's rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        1e6 / f64::from(self.cycle_us)
    }
}

/// One drive as the emulator's `status` command reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveStatus {
    /// The line as printed.
    pub line: String,
    /// CiA 402 state, as printed (e.g. "Fault").
    pub state: String,
    /// 0x603F.
    pub error_code: u16,
    /// AL state (1, 2, 4, 8).
    pub al_state: u8,
    /// AL error bit.
    pub al_error: bool,
    /// AL status code.
    pub al_status_code: u16,
    /// Joint torque the drive applies (N·m).
    pub torque_nm: f64,
}

fn hex<T: TryFrom<u64>>(word: &str) -> Option<T> {
    let w = word.trim_start_matches("0x");
    u64::from_str_radix(w, 16)
        .ok()
        .and_then(|v| T::try_from(v).ok())
}

impl DriveStatus {
    /// Parses `drive I: STATE statusword 0x.. error 0x.. al 0x..[+err] code 0x.. q .. rad
    /// torque .. N·m`.
    fn parse(line: &str) -> Option<Self> {
        let rest = line.split_once(": ")?.1;
        let (state, rest) = rest.split_once(" statusword ")?;
        let words: Vec<&str> = rest.split_whitespace().collect();
        let after = |key: &str| {
            words
                .iter()
                .position(|w| *w == key)
                .and_then(|i| words.get(i + 1))
                .copied()
        };
        let al = after("al")?;
        let (al_word, al_error) = match al.strip_suffix("+err") {
            Some(a) => (a, true),
            None => (al, false),
        };
        Some(Self {
            line: line.to_string(),
            state: state.to_string(),
            error_code: hex(after("error")?)?,
            al_state: hex(al_word)?,
            al_error,
            al_status_code: hex(after("code")?)?,
            torque_nm: after("torque")?.parse().ok()?,
        })
    }
}

/// The running emulator and what the tests need to drive the pipeline against it.
pub struct Rig {
    pub opts: RigOptions,
    pub dir: tempfile::TempDir,
    pub driver: PathBuf,
    emu: Child,
    control: ChildStdin,
    lines: Receiver<String>,
}

impl Drop for Rig {
    fn drop(&mut self) {
        let _ = self.emu.kill();
        let _ = self.emu.wait();
    }
}

impl Rig {
    /// The namespace, the veth pair and the emulated seed arm on it; `None` when not
    /// permitted (the test then passes, see the module).
    pub fn start(opts: RigOptions) -> Option<Rig> {
        if !private_netns_with_veth() {
            return None;
        }
        let driver = driver_binary();
        let emulator = workspace_binary(
            "microrobot-ethercat-emulator",
            "microrobot-ethercat-emulator",
            &["drivers/ethercat-cia402", "drivers/ethercat-emulator"],
        );
        let cycle_s = format!("{}", f64::from(opts.cycle_us) * 1e-6);
        let mut args = vec!["--interface", CHAIN_IF, "--seed-arm"];
        if opts.time_per_exchange {
            args.extend(["--cycle-s", &cycle_s]);
        }
        let mut emu = Command::new(&emulator)
            .args(&args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("start the emulator");
        let stdout = emu.stdout.take().expect("piped stdout");
        let control = emu.stdin.take().expect("piped stdin");
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let rig = Rig {
            opts,
            dir: tempfile::tempdir().expect("tempdir"),
            driver,
            emu,
            control,
            lines,
        };
        let ready = rig
            .lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the emulator is ready within 10 s");
        assert!(ready.starts_with("ready: 6 drives"), "{ready}");
        Some(rig)
    }

    /// Sends one control line to the emulator and returns its answer (the lines up to
    /// and including `ok`); panics on `error: …`.
    pub fn emulator(&mut self, command: &str) -> Vec<String> {
        writeln!(self.control, "{command}").expect("write to the emulator");
        self.control.flush().expect("flush");
        let mut out = Vec::new();
        loop {
            let line = self
                .lines
                .recv_timeout(Duration::from_secs(10))
                .unwrap_or_else(|e| panic!("emulator: no answer to `{command}`: {e}"));
            assert!(!line.starts_with("error"), "emulator `{command}`: {line}");
            let done = line == "ok";
            out.push(line);
            if done {
                return out;
            }
        }
    }

    /// Every drive as the emulator sees it now.
    pub fn drives(&mut self) -> Vec<DriveStatus> {
        let lines = self.emulator("status");
        let drives: Vec<DriveStatus> = lines
            .iter()
            .filter(|l| l.starts_with("drive "))
            .map(|l| DriveStatus::parse(l).unwrap_or_else(|| panic!("status line: {l}")))
            .collect();
        assert_eq!(drives.len(), 6, "{lines:?}");
        drives
    }

    /// The example drive file with the rig's cycle, lost-cycle limit and watchdog.
    pub fn drive_file(&self) -> PathBuf {
        let o = &self.opts;
        let path = self.dir.path().join("seed.drive.toml");
        let text = include_str!("../../drivers/ethercat-cia402/example.drive.toml")
            .replace("cycle_us = 1000", &format!("cycle_us = {}", o.cycle_us))
            .replace(
                "max_lost_cycles = 3",
                &format!("max_lost_cycles = {}", o.max_lost_cycles),
            )
            .replace(
                "drive_watchdog_ms = 10",
                &format!("drive_watchdog_ms = {}", o.drive_watchdog_ms),
            );
        std::fs::write(&path, text).expect("write the drive file");
        path
    }

    /// The `[actuator] command` line that runs the driver on the rig.
    pub fn actuator_table(&self) -> String {
        format!(
            "[actuator]\ncommand = [\"{}\", \"--instance\", \"{{instance}}\", \"--rate-hz\", \"{{rate_hz}}\", \"--drive-file\", \"{}\", \"--interface\", \"{MASTER_IF}\"]\n",
            self.driver.display(),
            self.drive_file().display()
        )
    }

    /// A pipeline config for `instance` on the seed arm with the driver as the actuator:
    /// the rig's rate, `lockstep`, `top_level` lines and `tables` appended.
    pub fn pipeline_config(
        &self,
        instance: &str,
        lockstep: bool,
        top_level: &str,
        tables: &str,
    ) -> PathBuf {
        write_config(
            self.dir.path(),
            instance,
            &format!(
                "lockstep = {lockstep}\nrate_hz = {}\n{top_level}",
                self.opts.rate_hz()
            ),
            &format!("{}\n{tables}", self.actuator_table()),
        )
    }
}
