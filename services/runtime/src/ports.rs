//! A stage's ports on the bus: an [`Inbox`] subscribes to a typed [`Topic`] (and, when
//! the stage wakes on it, listens to its event) and hands each message over with its
//! publisher and where that publisher comes from; an [`Outbox`] publishes and notifies.
//! The drain rule, the copy out of shared memory and the provenance lookup live here
//! once instead of in every service.

use std::cell::RefCell;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{DegradationAction, DegradationCause, DegradationInfo};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use microrobot_messages::{Topic, open_event, open_publish_subscribe, service_name};

use crate::provenance::{Origin, Provenance};

/// A bus payload: plain `#[repr(C)]` data that iceoryx2 can share and a stage copies.
pub trait Payload: std::fmt::Debug + Copy + ZeroCopySend + 'static {}

impl<T: std::fmt::Debug + Copy + ZeroCopySend + 'static> Payload for T {}

/// How an [`Inbox`] subscribes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Subscription {
    /// Samples a late joiner asks for (the contract keeps one: the measured state a
    /// planner starts from).
    pub history: usize,
    /// Samples the subscriber may queue (`None`: iceoryx2's default for the service).
    pub queue: Option<usize>,
    /// Whether the stage wakes on the stream's event (a listener is opened for the
    /// reactor); otherwise the inbox is polled when the stage wakes for something else.
    pub wakes: bool,
}

impl Subscription {
    /// A cyclic stream the stage wakes on: the contract's full queue, no history.
    pub const CYCLIC: Self = Self {
        history: 0,
        queue: Some(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER),
        wakes: true,
    };

    /// This subscription with a history of `n` samples.
    pub const fn with_history(self, n: usize) -> Self {
        Self { history: n, ..self }
    }

    /// This subscription, polled rather than woken on.
    pub const fn polled(self) -> Self {
        Self {
            wakes: false,
            ..self
        }
    }

    /// This subscription with iceoryx2's default queue.
    pub const fn default_queue(self) -> Self {
        Self {
            queue: None,
            ..self
        }
    }
}

/// One message taken from an [`Inbox`]: a copy of the payload and who published it.
pub struct Received<'a, T: Payload> {
    /// The payload, copied out of shared memory (the sample is released at once).
    pub msg: T,
    /// iceoryx2's unique id of the publisher.
    pub publisher: u128,
    inbox: &'a Inbox<T>,
}

impl<T> Received<'_, T>
where
    T: Payload,
{
    /// Whether the publisher's process was started by the pipeline's supervisor (always
    /// true without one; see [`crate::provenance`]). Looks the publisher up once, then
    /// answers from a cache: ask it only for a publisher the stream does not follow.
    pub fn from_pipeline(&self) -> bool {
        self.inbox
            .provenance
            .borrow_mut()
            .check(&self.inbox.service, self.publisher)
            == Origin::Pipeline
    }
}

/// A subscriber to one typed stream, with its listener when the stage wakes on it.
pub struct Inbox<T: Payload> {
    service: PortFactory<ipc::Service, T, ()>,
    subscriber: Subscriber<ipc::Service, T, ()>,
    listener: Option<Listener<ipc::Service>>,
    // Interior mutability: the reactor holds the ports by shared reference; the cache
    // is touched only on a new publisher, never across threads.
    provenance: RefCell<Provenance>,
    name: String,
    receive_failures: Failures,
}

impl<T> Inbox<T>
where
    T: Payload,
{
    /// Subscribes to `topic` of `instance` as `how` says. Provenance is checked against
    /// the supervisor named in the environment ([`Provenance::from_env`]).
    pub fn open(
        node: &Node<ipc::Service>,
        instance: &str,
        topic: Topic<T>,
        how: Subscription,
    ) -> anyhow::Result<Self> {
        let name = service_name(instance, topic.kind());
        let service = open_publish_subscribe::<T>(node, instance, topic.kind())?;
        let builder = service
            .subscriber_builder()
            .history_request(how.history)
            .set_degradation_handler(connection_failed(name.clone(), "subscriber"));
        let builder = match how.queue {
            Some(n) => builder.buffer_size(n),
            None => builder,
        };
        let subscriber = builder
            .create()
            .map_err(|e| anyhow::anyhow!("cannot subscribe to {name}: {e:?}"))?;
        let listener = if how.wakes {
            Some(
                open_event(node, instance, topic.kind())?
                    .listener_builder()
                    .create()
                    .map_err(|e| anyhow::anyhow!("cannot listen to {name}: {e:?}"))?,
            )
        } else {
            None
        };
        Ok(Self {
            service,
            subscriber,
            listener,
            provenance: RefCell::new(Provenance::from_env()),
            name,
            receive_failures: Failures::default(),
        })
    }

    /// The listener to register with the reactor (`None` for a polled inbox).
    pub fn listener(&self) -> Option<&Listener<ipc::Service>> {
        self.listener.as_ref()
    }

    /// Registers the inbox's listener with `reactor` (`None` for a polled inbox).
    pub fn register<'p>(
        &'p self,
        reactor: &mut crate::Reactor<'p>,
    ) -> std::io::Result<Option<crate::Source>> {
        self.listener.as_ref().map(|l| reactor.add(l)).transpose()
    }

    /// [`Self::register`] for an inbox the stage wakes on: a polled one is an error
    /// naming the stream.
    pub fn wake_on<'p>(
        &'p self,
        reactor: &mut crate::Reactor<'p>,
    ) -> std::io::Result<crate::Source> {
        self.register(reactor)?.ok_or_else(|| {
            std::io::Error::other(format!("{} is polled: nothing to wake on", self.name))
        })
    }

    /// The stream's service name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Consumes the pending wake-ups (the listener stays ready until they are read).
    #[inline]
    pub fn clear_events(&self) {
        if let Some(l) = &self.listener {
            let _ = l.try_wait(|_| {});
        }
    }

    /// The next queued message, if any. A receive error counts as none (the stream's
    /// sequence numbers show what was lost) and is logged, the first time and at each
    /// power of two of their count.
    #[inline]
    pub fn next(&self) -> Option<Received<'_, T>> {
        let sample = match self.subscriber.receive() {
            Ok(s) => s?,
            Err(e) => {
                self.receive_failures.record(&self.name, "receive", &e);
                return None;
            }
        };
        let msg = *sample;
        let publisher = sample.header().publisher_id().value();
        drop(sample);
        Some(Received {
            msg,
            publisher,
            inbox: self,
        })
    }

    /// Calls `f` with every queued message, oldest first.
    #[inline]
    pub fn for_each(&self, mut f: impl FnMut(Received<'_, T>)) {
        while let Some(r) = self.next() {
            f(r);
        }
    }

    /// The drain rule: every queued message, then the pending wake-ups, then every
    /// message that came meanwhile. Every queued message, not one per event: a sample
    /// can become visible after its notification (a sender's new connection), and
    /// events coalesce. The wake-ups are consumed after the messages, not before: that
    /// read is a syscall (about 1.3 µs on the reference VM) and would otherwise sit
    /// between the wake-up and the answer. A notifier sends no wake-up while one is
    /// pending, so what arrived before the wake-ups were consumed is taken by the
    /// second pass, and what arrives after wakes the stage again.
    #[inline]
    pub fn drain(&self, mut f: impl FnMut(Received<'_, T>)) {
        self.for_each(&mut f);
        if self.listener.is_some() {
            self.clear_events();
            self.for_each(f);
        }
    }

    /// An inbox taken on demand (commands): [`Self::drain`] when its own event woke the
    /// stage (`woken`), every queued message at the runner's sweep (`sweep`,
    /// [`crate::Cycle::sweep`]: what came without its event, and the connection to a new
    /// publisher made before that publisher can leave), nothing otherwise.
    #[inline]
    pub fn take_on_demand(&self, woken: bool, sweep: bool, f: impl FnMut(Received<'_, T>)) {
        if woken {
            self.drain(f);
        } else if sweep {
            self.for_each(f);
        }
    }
}

/// A publisher of one typed stream and the notifier that wakes its subscribers.
pub struct Outbox<T: Payload> {
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
    name: String,
    send_failures: Failures,
}

impl<T> Outbox<T>
where
    T: Payload,
{
    /// Publishes on `topic` of `instance`.
    pub fn open(
        node: &Node<ipc::Service>,
        instance: &str,
        topic: Topic<T>,
    ) -> anyhow::Result<Self> {
        let name = service_name(instance, topic.kind());
        let publisher = open_publish_subscribe::<T>(node, instance, topic.kind())?
            .publisher_builder()
            .set_degradation_handler(connection_failed(name.clone(), "publisher"))
            .create()
            .map_err(|e| anyhow::anyhow!("cannot publish on {name}: {e:?}"))?;
        let notifier = open_event(node, instance, topic.kind())?
            .notifier_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("cannot notify on {name}: {e:?}"))?;
        Ok(Self {
            publisher,
            notifier,
            name,
            send_failures: Failures::default(),
        })
    }

    /// Sends `msg` and wakes the subscribers; `false` when it could not be sent (logged,
    /// the first time and at each power of two of the failures' count).
    #[inline]
    pub fn send(&self, msg: T) -> bool {
        match self.publisher.send_copy(msg) {
            Ok(_) => {
                let _ = self.notifier.notify();
                true
            }
            Err(e) => {
                self.send_failures.record(&self.name, "send", &e);
                false
            }
        }
    }

    /// Hands the stored history to subscribers that joined since the last send.
    pub fn update_connections(&self) {
        let _ = self.publisher.update_connections();
    }
}

/// The failed calls of one port: counted, and logged the first time and at each power of
/// two of their count, so a persistent failure is seen without a log line per cycle.
#[derive(Default)]
struct Failures(std::cell::Cell<u64>);

impl Failures {
    /// Off the hot path: only a failed call comes here.
    #[cold]
    #[inline(never)]
    fn record(&self, stream: &str, call: &str, error: &dyn std::fmt::Debug) {
        let n = self.0.get().saturating_add(1);
        self.0.set(n);
        if n.is_power_of_two() {
            tracing::warn!("{stream}: {call} failed ({n} times so far): {error:?}");
        }
    }
}

/// The degradation handler of every port: a connection iceoryx2 could not establish (or
/// found corrupted) is logged with the stream and both ports, where iceoryx2's own
/// warning would fall below the services' log level. The port carries on with its other
/// connections, as iceoryx2's default does.
fn connection_failed(
    stream: String,
    side: &'static str,
) -> impl Fn(DegradationCause, &DegradationInfo) -> DegradationAction + Send + 'static {
    move |cause, info| {
        let what = match cause {
            DegradationCause::FailedToEstablishConnection => "could not connect",
            DegradationCause::ConnectionCorrupted => "found a corrupted connection",
        };
        tracing::warn!(
            "{stream}: the {side} {what} (publisher port {:032x}, subscriber port {:032x})",
            info.sender_port_id,
            info.receiver_port_id
        );
        DegradationAction::Ignore
    }
}
