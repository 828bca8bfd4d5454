//! The runner's sweep ([`Cycle::sweep`]): an inbox a stage takes only when its own event
//! wakes it is also looked at on the first wake-up at least [`SWEEP_NS`] after the last
//! sweep. So a message whose wake-up never came is taken at the next sweep, and a
//! short-lived sender that waits 20 ms before sending (as `microrobot send` does) is
//! connected to in time: its command survives its departure even while the stage is
//! blocked.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use microrobot_messages::{
    MotionCommand, ServiceRole, ServiceStatus, monotonic_ns, open_publish_subscribe, topic,
};
use microrobot_runtime::node::named_node;
use microrobot_runtime::{
    Cycle, Inbox, Outbox, Reactor, Ready, SWEEP_NS, Shutdown, Source, Stage, Subscription, TimerFd,
    serve,
};

mod common;

/// The stage's tick: a 4 kHz cycle, four wake-ups per sweep when nothing is late.
const TICK_NS: u64 = 250_000;

/// What the stage saw: a command taken (its seq, and whether its own event woke the
/// stage), a sweep, or that it is about to block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seen {
    Command { seq: u64, woken: bool },
    Sweep,
    Blocking,
}

struct Ports {
    commands: Inbox<MotionCommand>,
    tick: TimerFd,
}

#[derive(Clone, Copy)]
struct Sources {
    command: Source,
    tick: Source,
}

/// Ticks at 4 kHz and takes commands the way the planner and the actuator do
/// (`Inbox::take_on_demand`): on their event, or at the sweep. When `block` is set, its next wake-up blocks for 100 ms
/// first (a lifecycle hook that takes its time).
struct Sweeper {
    seen: mpsc::Sender<Seen>,
    block: Arc<AtomicBool>,
}

impl Stage for Sweeper {
    type Ports = Ports;
    type Sources = Sources;

    fn register<'p>(ports: &'p Ports, reactor: &mut Reactor<'p>) -> std::io::Result<Sources> {
        Ok(Sources {
            command: ports.commands.wake_on(reactor)?,
            tick: reactor.add(&ports.tick)?,
        })
    }

    fn wake(
        &mut self,
        ports: &Ports,
        on: Sources,
        ready: Ready,
        cycle: &mut Cycle<'_>,
    ) -> anyhow::Result<()> {
        if ready.contains(on.tick) {
            let _ = ports.tick.read_expirations();
        }
        if self.block.swap(false, Ordering::SeqCst) {
            let _ = self.seen.send(Seen::Blocking);
            std::thread::sleep(Duration::from_millis(100));
        }
        if cycle.sweep {
            let _ = self.seen.send(Seen::Sweep);
        }
        let woken = ready.contains(on.command);
        ports.commands.take_on_demand(woken, cycle.sweep, |r| {
            let _ = self.seen.send(Seen::Command {
                seq: r.msg.seq,
                woken,
            });
        });
        Ok(())
    }

    fn report(&self, _status: &mut ServiceStatus) {}
}

/// The next message other than a sweep, counting the sweeps before it.
fn next_other(seen: &mpsc::Receiver<Seen>, sweeps: &mut u32) -> Seen {
    let give_up = Instant::now() + Duration::from_secs(10);
    loop {
        let left = give_up.saturating_duration_since(Instant::now());
        match seen.recv_timeout(left) {
            Ok(Seen::Sweep) => *sweeps += 1,
            Ok(other) => return other,
            Err(e) => panic!("nothing but sweeps for 10 s ({e}); sweeps seen {sweeps}"),
        }
    }
}

fn command(seq: u64) -> MotionCommand {
    MotionCommand {
        seq,
        ..MotionCommand::default()
    }
}

/// Runs a [`Sweeper`] on the `command` stream of a fresh instance while `body` runs.
fn with_sweeper(body: impl FnOnce(&str, &mpsc::Receiver<Seen>, &AtomicBool)) {
    let instance = format!("sweep{}-{}", std::process::id(), monotonic_ns() % 1_000_000);
    let cfg = common::plain_config(&instance);
    let shutdown = Shutdown::new().unwrap();
    let (tx, seen) = mpsc::channel();
    let block = Arc::new(AtomicBool::new(false));
    let runner = {
        let (cfg, shutdown, block) = (cfg.clone(), shutdown.clone(), block.clone());
        std::thread::spawn(move || {
            serve(&cfg, &shutdown, ServiceRole::Planner, |setup| {
                let commands = Inbox::open(
                    setup.node,
                    setup.instance(),
                    topic::COMMAND,
                    Subscription::CYCLIC.default_queue(),
                )?;
                let tick = TimerFd::new()?;
                tick.arm_absolute(monotonic_ns() + TICK_NS, TICK_NS)?;
                Ok(Some((
                    Sweeper { seen: tx, block },
                    Ports { commands, tick },
                )))
            })
        })
    };
    // The first wake-up sweeps.
    assert_eq!(
        seen.recv_timeout(Duration::from_secs(10)).unwrap(),
        Seen::Sweep
    );
    body(&instance, &seen, &block);
    shutdown.request();
    runner.join().unwrap().unwrap();
}

#[test]
fn a_command_without_its_wake_up_is_taken_at_the_next_sweep_and_one_with_it_at_once() {
    with_sweeper(|instance, seen, _| {
        let node = named_node(&format!("sweep.{}", std::process::id())).unwrap();
        // Published without a notification: only a sweep can take it.
        let silent =
            open_publish_subscribe::<MotionCommand>(&node, instance, topic::COMMAND.kind())
                .unwrap()
                .publisher_builder()
                .create()
                .unwrap();
        while seen.try_recv().is_ok() {}
        let mut sweeps = 0;
        silent.send_copy(command(1)).unwrap();
        let taken = next_other(seen, &mut sweeps);
        assert_eq!(
            taken,
            Seen::Command {
                seq: 1,
                woken: false
            }
        );
        // A sweep under way as it was sent may have missed it; the next one takes it.
        assert!(sweeps <= 2, "{sweeps} sweeps passed the queued command by");

        // With its wake-up, a command is taken by the wake-up its event causes.
        let outbox = Outbox::open(&node, instance, topic::COMMAND).unwrap();
        assert!(outbox.send(command(2)));
        let mut sweeps = 0;
        assert_eq!(
            next_other(seen, &mut sweeps),
            Seen::Command {
                seq: 2,
                woken: true
            }
        );
    });
}

#[test]
fn sweeps_come_at_most_once_per_sweep_interval() {
    with_sweeper(|_, seen, _| {
        while seen.try_recv().is_ok() {}
        let window = Instant::now();
        std::thread::sleep(Duration::from_millis(300));
        let mut sweeps = 0u32;
        while let Ok(s) = seen.try_recv() {
            assert_eq!(s, Seen::Sweep);
            sweeps += 1;
        }
        let intervals = window.elapsed().as_nanos() as f64 / SWEEP_NS as f64;
        // At most one per interval (and one more at each end of the window); and they do
        // come while the stage keeps waking (ticks at 4 kHz).
        assert!(
            f64::from(sweeps) <= intervals + 2.0,
            "{sweeps} sweeps in {intervals:.0} sweep intervals"
        );
        assert!(
            sweeps >= 2,
            "{sweeps} sweeps in {intervals:.0} sweep intervals"
        );
    });
}

#[test]
fn a_short_lived_senders_command_outlives_it_while_the_stage_is_blocked() {
    with_sweeper(|instance, seen, block| {
        // A sender as `microrobot send`: its publisher exists 20 ms before it sends.
        let node = named_node(&format!("sweep-send.{}", std::process::id())).unwrap();
        let outbox = Outbox::open(&node, instance, topic::COMMAND).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        // The stage blocks (a hook that takes 100 ms) before the command is sent, and the
        // sender is gone before the stage wakes again.
        block.store(true, Ordering::SeqCst);
        let mut sweeps = 0;
        assert_eq!(next_other(seen, &mut sweeps), Seen::Blocking);
        assert!(outbox.send(command(7)));
        drop(outbox);
        drop(node);
        let mut sweeps = 0;
        match next_other(seen, &mut sweeps) {
            Seen::Command { seq: 7, .. } => {}
            other => panic!("expected command 7 after the block, saw {other:?}"),
        }
    });
}
