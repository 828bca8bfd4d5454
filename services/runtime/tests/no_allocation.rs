//! What one bus hop of a service's cycle allocates, under a counting global allocator
//! that counts this thread's allocations (the cycle's math is covered by the model
//! crate's test of the same name): notify, [`Reactor::wait`], draining the listener and
//! receiving the sample allocate nothing. Publishing allocates exactly once: iceoryx2
//! 0.10 puts each loaned sample's bookkeeping (`ChunkMutSharedState`) in a fresh `Arc`,
//! in `Publisher::loan_uninit`, which `send_copy` calls. That is a library limitation
//! (a small thread-cached malloc, no syscall once warm, memory locked by `mlockall`),
//! pinned here so that an iceoryx2 upgrade which removes it, or adds more, is noticed.

use std::cell::Cell;

use microrobot_messages::{
    JointSetpoint, ServiceKind, monotonic_ns, open_event, open_publish_subscribe,
};
use microrobot_runtime::node::named_node;
use microrobot_runtime::reactor::Reactor;
use microrobot_runtime::{Shutdown, TimerFd};

#[path = "../../../tests/support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

#[test]
fn waiting_on_the_reactor_and_one_bus_hop_allocate_nothing() {
    let instance = format!("noalloc{}", std::process::id());
    let node = named_node(&format!("noalloc.{}", std::process::id())).unwrap();
    let pubsub =
        open_publish_subscribe::<JointSetpoint>(&node, &instance, ServiceKind::Setpoint).unwrap();
    let event = open_event(&node, &instance, ServiceKind::Setpoint).unwrap();
    let publisher = pubsub.publisher_builder().create().unwrap();
    let subscriber = pubsub.subscriber_builder().create().unwrap();
    let notifier = event.notifier_builder().create().unwrap();
    let listener = event.listener_builder().create().unwrap();
    let timer = TimerFd::new().unwrap();
    let shutdown = Shutdown::new().unwrap();

    let mut reactor = Reactor::new().unwrap();
    let on_setpoint = reactor.add(&listener).unwrap();
    let on_timer = reactor.add(&timer).unwrap();
    let on_stop = reactor.add(&shutdown).unwrap();

    let publish_allocations = Cell::new(0);
    let mut hop = |seq: u64| {
        let mut sp = JointSetpoint::default();
        sp.header.seq = seq;
        let before_publish = allocations();
        publisher.send_copy(sp).unwrap();
        publish_allocations.set(publish_allocations.get() + allocations() - before_publish);
        notifier.notify().unwrap();
        let ready = reactor.wait_ms(5_000).unwrap();
        assert!(ready.contains(on_setpoint));
        assert!(!ready.contains(on_timer) && !ready.contains(on_stop));
        listener.try_wait(|_| {}).unwrap();
        let mut got = 0;
        while let Some(s) = subscriber.receive().unwrap() {
            got = s.header.seq;
        }
        assert_eq!(got, seq);
        assert!(
            reactor.wait_ms(0).unwrap().is_empty(),
            "drained listener still ready"
        );
    };
    // Warm up: first use of a connection may set things up.
    for seq in 1..=3 {
        hop(seq);
    }
    let before = allocations();
    publish_allocations.set(0);
    for seq in 4..=1003 {
        hop(seq);
    }
    let total = allocations() - before;
    let publish = publish_allocations.get();
    assert_eq!(
        total - publish,
        0,
        "allocations outside send_copy in 1000 hops"
    );
    assert_eq!(
        publish, 1000,
        "iceoryx2's send_copy allocated {publish} times in 1000 publishes (0.10 does once \
         per sample): update this test and services/README's cost notes"
    );

    // The timer and the shutdown fd report as themselves, still without allocating.
    timer.arm_absolute(monotonic_ns(), 0).unwrap();
    shutdown.request();
    let before = allocations();
    let ready = reactor.wait_ms(5_000).unwrap();
    assert!(ready.contains(on_stop));
    let _ = timer.read_expirations();
    assert_eq!(allocations() - before, 0);
}
