//! Service names and the single place where every service is opened, so all processes
//! (ours, a driver's, a Python client's) ask for identical QoS settings. iceoryx2 lets
//! the first creator's settings win, so they must never differ between processes.

use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::CONTRACT_VERSION;

/// The streams of one pipeline instance. Each is a publish-subscribe service and an
/// event service of the same name (data + wake-up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind {
    /// [`crate::JointSetpoint`], planner → dynamics, one per tick.
    Setpoint,
    /// [`crate::TorqueCommand`], dynamics → actuator, one per setpoint.
    Torque,
    /// [`crate::JointState`], actuator → planner and dynamics, one per plant step.
    State,
    /// [`crate::MotionCommand`], any client → planner.
    Command,
    /// [`crate::ServiceStatus`], every service → supervisor and monitors, ~10 Hz.
    Status,
    /// [`crate::MasterPose`], master device (or `microrobot teleop-source`) → planner.
    Master,
}

impl ServiceKind {
    /// Every stream, in pipeline order.
    pub const ALL: [ServiceKind; 6] = [
        Self::Setpoint,
        Self::Torque,
        Self::State,
        Self::Command,
        Self::Status,
        Self::Master,
    ];

    /// The stream's name inside an instance.
    pub fn stream_name(self) -> &'static str {
        match self {
            Self::Setpoint => "setpoint",
            Self::Torque => "torque",
            Self::State => "state",
            Self::Command => "command",
            Self::Status => "status",
            Self::Master => "master",
        }
    }
}

/// QoS shared by every publish-subscribe service of the contract.
pub mod qos {
    /// Samples a subscriber may queue, sized in time: 64 ms of a 4 kHz stream (256 ms at
    /// 1 kHz), so a service frozen by a host stall of tens of ms finds every message when
    /// it wakes (a 20 ms stall at 4 kHz queues 80 setpoints and then a burst of 80
    /// torques), and a lockstep subscriber woken late does too. A full queue overwrites
    /// its oldest sample, which the subscriber sees as a sequence gap.
    pub const SUBSCRIBER_BUFFER: usize = 256;
    /// Late joiners get the last sample (the planner starts from the measured state).
    pub const HISTORY: usize = 1;
    /// Publishers per service: one owner plus room for a restarted process whose dead
    /// predecessor was not yet cleaned, and for command senders.
    pub const MAX_PUBLISHERS: usize = 8;
    /// Subscribers per service: the pipeline, supervisor, recorder, `top`, tests.
    pub const MAX_SUBSCRIBERS: usize = 16;
    /// Nodes per service.
    pub const MAX_NODES: usize = 32;
    /// Notifiers and listeners per event service.
    pub const MAX_EVENT_PORTS: usize = 16;
    /// Largest event id of an event service: every notification is a plain `notify()`
    /// (id 0). A listener's wake-up clears one counter per possible id, an atomic swap on
    /// shared memory each, so iceoryx2's default of 255 cost 256 swaps (32 cache lines)
    /// per drained listener and wake-up.
    pub const EVENT_ID_MAX: usize = 0;
}

/// Failure to open a service of the contract.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    #[error("invalid service name `{name}`: {reason}")]
    Name { name: String, reason: String },
    #[error(
        "cannot open `{name}`: {reason} (a different contract version or QoS? this build speaks microrobot::v{CONTRACT_VERSION})"
    )]
    Open { name: String, reason: String },
}

/// The full service name of `kind` in pipeline `instance`: `microrobot/v2/<instance>/<stream>`.
pub fn service_name(instance: &str, kind: ServiceKind) -> String {
    format!(
        "microrobot/v{CONTRACT_VERSION}/{instance}/{}",
        kind.stream_name()
    )
}

fn to_service_name(name: &str) -> Result<ServiceName, BusError> {
    ServiceName::new(name).map_err(|e| BusError::Name {
        name: name.to_string(),
        reason: format!("{e:?}"),
    })
}

/// A stream of the contract with its payload type: `Topic<JointSetpoint>` can only be
/// opened as setpoints, so a process cannot subscribe to one stream with another's
/// payload (iceoryx2 would refuse it at run time; this refuses it at compile time).
#[derive(Debug)]
pub struct Topic<T> {
    kind: ServiceKind,
    _payload: std::marker::PhantomData<fn() -> T>,
}

impl<T> Clone for Topic<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Topic<T> {}

impl<T> Topic<T> {
    const fn new(kind: ServiceKind) -> Self {
        Self {
            kind,
            _payload: std::marker::PhantomData,
        }
    }

    /// The stream.
    pub const fn kind(self) -> ServiceKind {
        self.kind
    }
}

/// The typed streams of the contract, one per [`ServiceKind`].
pub mod topic {
    use super::{ServiceKind, Topic};
    use crate::{
        JointSetpoint, JointState, MasterPose, MotionCommand, ServiceStatus, TorqueCommand,
    };

    /// Planner → dynamics.
    pub const SETPOINT: Topic<JointSetpoint> = Topic::new(ServiceKind::Setpoint);
    /// Dynamics → actuator.
    pub const TORQUE: Topic<TorqueCommand> = Topic::new(ServiceKind::Torque);
    /// Actuator → planner and dynamics.
    pub const STATE: Topic<JointState> = Topic::new(ServiceKind::State);
    /// Any client → planner (and the actuator's reset).
    pub const COMMAND: Topic<MotionCommand> = Topic::new(ServiceKind::Command);
    /// Every service → supervisor and monitors.
    pub const STATUS: Topic<ServiceStatus> = Topic::new(ServiceKind::Status);
    /// Master device → planner.
    pub const MASTER: Topic<MasterPose> = Topic::new(ServiceKind::Master);
}

/// Opens (or creates) the publish-subscribe service `kind` of `instance` with the
/// contract's QoS. `T` must be the payload type of `kind`.
pub fn open_publish_subscribe<T>(
    node: &Node<ipc::Service>,
    instance: &str,
    kind: ServiceKind,
) -> Result<publish_subscribe::PortFactory<ipc::Service, T, ()>, BusError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let name = service_name(instance, kind);
    node.service_builder(&to_service_name(&name)?)
        .publish_subscribe::<T>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(qos::SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(2)
        .history_size(qos::HISTORY)
        .max_publishers(qos::MAX_PUBLISHERS)
        .max_subscribers(qos::MAX_SUBSCRIBERS)
        .max_nodes(qos::MAX_NODES)
        .open_or_create()
        .map_err(|e| BusError::Open {
            name,
            reason: format!("{e:?}"),
        })
}

/// Opens (or creates) the event service paired with `kind` of `instance`.
pub fn open_event(
    node: &Node<ipc::Service>,
    instance: &str,
    kind: ServiceKind,
) -> Result<event::PortFactory<ipc::Service>, BusError> {
    let name = service_name(instance, kind);
    node.service_builder(&to_service_name(&name)?)
        .event()
        .max_listeners(qos::MAX_EVENT_PORTS)
        .max_notifiers(qos::MAX_EVENT_PORTS)
        .event_id_max_value(qos::EVENT_ID_MAX)
        .max_nodes(qos::MAX_NODES)
        .open_or_create()
        .map_err(|e| BusError::Open {
            name,
            reason: format!("{e:?}"),
        })
}
