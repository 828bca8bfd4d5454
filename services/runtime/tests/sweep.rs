//! The runner's sweep: an inbox a stage takes only when its own event wakes it is also
//! looked at once per status period ([`Cycle::sweep`]), so a message whose wake-up never
//! came is taken within a status period, and no more often than that.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use microrobot_messages::{
    MotionCommand, ServiceRole, ServiceStatus, monotonic_ns, open_publish_subscribe, topic,
};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::node::named_node;
use microrobot_runtime::{
    Cycle, Inbox, Outbox, Reactor, Ready, Shutdown, Source, Stage, Subscription, TimerFd, serve,
};

const STATUS_PERIOD_MS: f64 = 20.0;
const TICK_NS: u64 = 1_000_000;

/// What the stage saw: a command taken (its seq, and whether its own event woke the
/// stage), or a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seen {
    Command { seq: u64, woken: bool },
    Sweep,
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

/// Ticks every millisecond and takes commands the way the planner and the actuator do:
/// on their event, or at the sweep.
struct Sweeper {
    seen: mpsc::Sender<Seen>,
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
        if cycle.sweep {
            let _ = self.seen.send(Seen::Sweep);
        }
        let woken = ready.contains(on.command);
        if woken || cycle.sweep {
            ports.commands.drain(|r| {
                let _ = self.seen.send(Seen::Command {
                    seq: r.msg.seq,
                    woken,
                });
            });
        }
        Ok(())
    }

    fn report(&self, _status: &mut ServiceStatus) {}
}

fn config(instance: &str) -> PipelineConfig {
    let mut cfg = PipelineConfig {
        instance: instance.into(),
        status_period_ms: STATUS_PERIOD_MS,
        ..PipelineConfig::default()
    };
    cfg.realtime.cpu_affinity.clear();
    cfg.realtime.pm_qos = false;
    cfg.realtime.sched_fifo_priority = 0;
    cfg.realtime.mlockall = false;
    cfg
}

/// Waits for the first command seen, counting the sweeps before it.
fn next_command(seen: &mpsc::Receiver<Seen>, sweeps: &mut u32) -> (u64, bool) {
    let give_up = Instant::now() + Duration::from_secs(5);
    loop {
        let left = give_up.saturating_duration_since(Instant::now());
        match seen.recv_timeout(left) {
            Ok(Seen::Command { seq, woken }) => return (seq, woken),
            Ok(Seen::Sweep) => *sweeps += 1,
            Err(e) => panic!("no command taken within 5 s ({e}); sweeps seen {sweeps}"),
        }
    }
}

fn command(seq: u64) -> MotionCommand {
    MotionCommand {
        seq,
        ..MotionCommand::default()
    }
}

#[test]
fn a_command_without_its_wake_up_is_taken_at_the_next_sweep() {
    let instance = format!("sweep{}", std::process::id());
    let cfg = config(&instance);
    let shutdown = Shutdown::new().unwrap();
    let (tx, seen) = mpsc::channel();
    let runner = {
        let (cfg, shutdown) = (cfg.clone(), shutdown.clone());
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
                Ok(Some((Sweeper { seen: tx }, Ports { commands, tick })))
            })
        })
    };

    // The first wake-up sweeps.
    assert_eq!(
        seen.recv_timeout(Duration::from_secs(5)).unwrap(),
        Seen::Sweep
    );

    let node = named_node(&format!("sweep.{}", std::process::id())).unwrap();
    // Published without a notification: only the sweep can take it.
    let silent = open_publish_subscribe::<MotionCommand>(&node, &instance, topic::COMMAND.kind())
        .unwrap()
        .publisher_builder()
        .create()
        .unwrap();
    let mut sweeps = 0;
    silent.send_copy(command(1)).unwrap();
    let sent = Instant::now();
    assert_eq!(next_command(&seen, &mut sweeps), (1, false));
    let waited = sent.elapsed();
    assert!(sweeps <= 1, "{sweeps} sweeps passed the queued command by");
    // A generous guard, not a timing claim: the sweep comes once per status period.
    assert!(waited < Duration::from_secs(2), "taken after {waited:?}");

    // With its wake-up, a command is taken by the wake-up its event causes.
    let outbox = Outbox::open(&node, &instance, topic::COMMAND).unwrap();
    assert!(outbox.send(command(2)));
    assert_eq!(next_command(&seen, &mut sweeps), (2, true));

    // The sweep comes once per status period, not at every one of the 1 ms ticks.
    sweeps = 0;
    let window = Instant::now();
    std::thread::sleep(Duration::from_millis(300));
    while let Ok(s) = seen.try_recv() {
        assert_eq!(s, Seen::Sweep);
        sweeps += 1;
    }
    let periods = window.elapsed().as_secs_f64() * 1e3 / STATUS_PERIOD_MS;
    assert!(
        sweeps >= 2 && f64::from(sweeps) <= periods + 2.0,
        "{sweeps} sweeps in {periods:.1} status periods"
    );

    shutdown.request();
    runner.join().unwrap().unwrap();
}
