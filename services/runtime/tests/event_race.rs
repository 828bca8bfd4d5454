//! A stage's wake-up is never lost to a notification that races its drain.
//!
//! iceoryx2 0.10's listener returned its shared state to idle before it emptied its
//! socket: a notifier that came in between sent a datagram the drain then read away,
//! left the state "notified", and every later notifier, finding it so, sent nothing;
//! the stage slept forever with messages queued (a lockstep pipeline stopped dead, a
//! free-running one lost its stream). The vendored `iceoryx2-cal` empties the socket
//! first. This test hammers one listener with notifications while threads that wake
//! every few microseconds preempt it at random points, as a loaded host does; with the
//! published order it loses its wake-up within seconds.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use microrobot_messages::{JointSetpoint, topic};
use microrobot_runtime::node::named_node;
use microrobot_runtime::{Inbox, Outbox, Reactor, Subscription};

/// Threads that sleep 20 µs and spin 5 µs: each wake-up may preempt the listener.
const PREEMPTERS: usize = 6;
/// How long the listener is hammered.
const RUN: Duration = Duration::from_secs(10);
/// A silence this long while the notifier keeps notifying is a lost wake-up (a lost
/// one never comes back, so the guard can be generous).
const SILENCE_MS: i32 = 2000;

#[test]
fn a_notification_racing_the_drain_never_loses_a_later_wake_up() {
    let pid = std::process::id();
    let instance = format!("evrace{pid}");
    let node = named_node(&format!("evrace.listener.{pid}")).unwrap();
    let inbox = Inbox::open(&node, &instance, topic::SETPOINT, Subscription::CYCLIC).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let sent = Arc::new(AtomicU64::new(0));

    let notifier = {
        let (stop, sent, instance) = (stop.clone(), sent.clone(), instance.clone());
        std::thread::spawn(move || {
            let node = named_node(&format!("evrace.notifier.{pid}")).unwrap();
            let outbox = Outbox::open(&node, &instance, topic::SETPOINT).unwrap();
            let mut sp = JointSetpoint::default();
            while !stop.load(Ordering::Relaxed) {
                sp.header.seq += 1;
                if outbox.send(sp) {
                    sent.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
    };
    let preempters: Vec<_> = (0..PREEMPTERS)
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_micros(20));
                    let t = Instant::now();
                    while t.elapsed() < Duration::from_micros(5) {}
                }
            })
        })
        .collect();

    let mut reactor = Reactor::new().unwrap();
    let on = inbox.wake_on(&mut reactor).unwrap();
    let end = Instant::now() + RUN;
    let (mut wakes, mut taken) = (0u64, 0u64);
    let mut lost = None;
    while Instant::now() < end {
        if !reactor.wait_ms(SILENCE_MS).unwrap().contains(on) {
            lost = Some(sent.load(Ordering::Relaxed));
            break;
        }
        wakes += 1;
        inbox.drain(|_| taken += 1);
    }
    stop.store(true, Ordering::Relaxed);
    notifier.join().unwrap();
    for p in preempters {
        p.join().unwrap();
    }
    eprintln!(
        "{wakes} wake-ups, {taken} messages taken of {} sent",
        sent.load(Ordering::Relaxed)
    );
    assert!(wakes > 1000, "the listener hardly ran: {wakes} wake-ups");
    assert!(
        lost.is_none(),
        "no wake-up for {SILENCE_MS} ms while the notifier kept notifying ({lost:?} sent, {taken} taken, {wakes} wake-ups)"
    );
}
