//! The drain rule of an [`Inbox`] the stage wakes on: every message published before or
//! during a drain is either handed over by that drain or wakes the stage again; none is
//! left queued behind a consumed wake-up.

use microrobot_messages::{JointSetpoint, topic};
use microrobot_runtime::node::named_node;
use microrobot_runtime::{Inbox, Outbox, Reactor, Subscription};

/// Drains once, publishing `during` more messages from inside the drain (one after
/// each message taken), and returns the sequence numbers taken.
fn drain_publishing(
    inbox: &Inbox<JointSetpoint>,
    outbox: &Outbox<JointSetpoint>,
    next_seq: &mut u64,
    during: &mut u32,
) -> Vec<u64> {
    let mut taken = Vec::new();
    inbox.drain(|r| {
        taken.push(r.msg.header.seq);
        if *during > 0 {
            *during -= 1;
            *next_seq += 1;
            let mut sp = JointSetpoint::default();
            sp.header.seq = *next_seq;
            assert!(outbox.send(sp));
        }
    });
    taken
}

#[test]
fn every_message_is_taken_by_the_drain_or_wakes_the_stage_again() {
    let instance = format!("drain{}", std::process::id());
    let node = named_node(&format!("drain.{}", std::process::id())).unwrap();
    let inbox = Inbox::open(&node, &instance, topic::SETPOINT, Subscription::CYCLIC).unwrap();
    let outbox = Outbox::open(&node, &instance, topic::SETPOINT).unwrap();
    let mut reactor = Reactor::new().unwrap();
    let on = inbox.wake_on(&mut reactor).unwrap();

    let mut seq = 0u64;
    let mut taken = Vec::new();
    for during in [0u32, 1, 3] {
        seq += 1;
        let mut sp = JointSetpoint::default();
        sp.header.seq = seq;
        assert!(outbox.send(sp));
        let mut during = during;
        // Wake-ups until the stage is idle: each drain takes what it can; what it leaves
        // must have woken the stage again.
        let mut wakes = 0;
        while reactor.wait_ms(0).unwrap().contains(on) {
            taken.extend(drain_publishing(&inbox, &outbox, &mut seq, &mut during));
            wakes += 1;
            assert!(wakes < 10, "the stage keeps waking: {taken:?}");
        }
        // Idle: nothing queued and no wake-up pending.
        assert!(
            inbox.next().is_none(),
            "a message left behind a consumed wake-up"
        );
        assert_eq!(taken, (1..=seq).collect::<Vec<_>>());
    }
    // Idle stays idle, and the next message wakes the stage.
    assert!(reactor.wait_ms(0).unwrap().is_empty());
    seq += 1;
    let mut sp = JointSetpoint::default();
    sp.header.seq = seq;
    assert!(outbox.send(sp));
    assert!(reactor.wait_ms(1_000).unwrap().contains(on));
}
