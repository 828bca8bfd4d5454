//! The emulator binary on one end of a veth pair, an unchanged ethercrab MainDevice with
//! its own raw-socket TX/RX task on the other, inside a network namespace of this test
//! thread's own (nothing is visible outside it and it vanishes with the thread).
//!
//! Needs CAP_NET_ADMIN (namespace, veth) and CAP_NET_RAW (AF_PACKET). Without them the
//! test prints why and passes, unless MICROROBOT_REQUIRE_NETNS=1, where it fails.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

use async_io::block_on;
use ethercrab::std::{ethercat_now, tx_rx_task};
use ethercrab::{MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use microrobot_ethercat_cia402::cia402::{Axis, Statusword, Target};

const MASTER_IF: &str = "ecat0";
const CHAIN_IF: &str = "ecat1";

/// Skips (prints the line) or, when required, fails.
fn not_permitted(why: &str) {
    let need = format!(
        "raw-socket test: needs CAP_NET_ADMIN and CAP_NET_RAW (network namespace, veth pair, AF_PACKET): {why}"
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

/// The emulator process, killed on drop.
struct Emu {
    child: Child,
    stdin: ChildStdin,
    lines: Receiver<String>,
}

impl Emu {
    fn start(args: &[&str]) -> Emu {
        let mut child = Command::new(env!("CARGO_BIN_EXE_microrobot-ethercat-emulator"))
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("start the emulator");
        let stdin = child.stdin.take().expect("piped stdin");
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Emu {
            child,
            stdin,
            lines,
        }
    }

    fn line(&self) -> String {
        self.lines
            .recv_timeout(Duration::from_secs(5))
            .expect("a line from the emulator within 5 s")
    }

    fn command(&mut self, cmd: &str) -> String {
        writeln!(self.stdin, "{cmd}").expect("write a command");
        self.line()
    }
}

impl Drop for Emu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn master_and_emulator_over_a_veth_pair_in_a_private_netns() {
    // SAFETY: unshare(2) changes only this thread's network namespace.
    if unsafe { libc::unshare(libc::CLONE_NEWNET) } != 0 {
        not_permitted(&format!(
            "unshare(CLONE_NEWNET): {}",
            std::io::Error::last_os_error()
        ));
        return;
    }
    let setup = ip(&[
        "link", "add", MASTER_IF, "type", "veth", "peer", "name", CHAIN_IF,
    ])
    .and_then(|()| ip(&["link", "set", MASTER_IF, "up"]))
    .and_then(|()| ip(&["link", "set", CHAIN_IF, "up"]));
    if let Err(e) = setup {
        not_permitted(&e);
        return;
    }

    let mut emu = Emu::start(&[
        "--interface",
        CHAIN_IF,
        "--drives",
        "2",
        "--cycle-s",
        "0.001",
    ]);
    let ready = emu.line();
    assert!(ready.starts_with("ready: 2 drives"), "{ready}");
    assert!(
        emu.command("frobnicate")
            .starts_with("error: unknown command")
    );
    assert!(
        emu.command("drive-fault 7 1")
            .starts_with("error: no drive 7")
    );

    let storage: &'static PduStorage<16, { PduStorage::element_size(1100) }> =
        Box::leak(Box::new(PduStorage::new()));
    let (tx, rx, pdu_loop) = storage.try_split().expect("split");
    let md = MainDevice::new(
        pdu_loop,
        Timeouts {
            pdu: Duration::from_millis(100),
            eeprom: Duration::from_millis(100),
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 100,
            ..Default::default()
        },
    );
    let io = tx_rx_task(MASTER_IF, tx, rx).expect("master raw socket");
    let body = async {
        let group = md
            .init_single_group::<4, 64>(ethercat_now)
            .await
            .expect("discovery over the veth pair");
        assert_eq!(group.len(), 2);
        for sd in group.iter(&md) {
            sd.sdo_write(0x6060, 0, 10i8).await.expect("CST");
        }
        let group = group.into_op(&md).await.expect("OP");
        let mut axes = [Axis::new(), Axis::new()];
        for a in axes.iter_mut() {
            a.set_target(Target::Enabled);
        }
        let mut faulted = None;
        for n in 0..60 {
            let resp = group.tx_rx(&md).await.expect("cycle");
            assert_eq!(resp.working_counter, 6);
            if n == 20 {
                assert!(axes.iter().all(|a| a.is_enabled()));
                assert_eq!(emu.command("drive-fault 1 0x2310"), "ok");
            }
            for (i, axis) in axes.iter_mut().enumerate() {
                let sd = group.subdevice(&md, i).expect("drive");
                let mut io = sd.io_raw_mut();
                let inp = io.inputs().to_vec();
                let sw = Statusword(u16::from_le_bytes([inp[0], inp[1]]));
                let err = u16::from_le_bytes([inp[12], inp[13]]);
                let step = axis.step(sw.state().expect("defined"), err);
                if step.fault.is_some() && faulted.is_none() {
                    faulted = Some((i, err, n));
                }
                io.outputs()[0..2].copy_from_slice(&step.controlword.bits().to_le_bytes());
            }
        }
        let (drive, code, at) = faulted.expect("the injected fault reached the master");
        assert_eq!((drive, code), (1, 0x2310));
        println!("fault injected before cycle 21 seen at cycle {at}");
    };
    block_on(futures_lite::future::or(
        async {
            body.await;
            Ok(())
        },
        async { io.await.map(|_| ()) },
    ))
    .expect("tx/rx task");
    let status = emu.command("status");
    assert!(status.starts_with("drive 0: Operation enabled"), "{status}");
}
