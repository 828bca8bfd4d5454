//! The supervisor's view of the measured-state stream: the last [`JointState`] the
//! actuator published, handed to a restarted actuator (see
//! `microrobot_actuator::resume`) so the simulated arm resumes where it was.

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use microrobot_messages::{JointState, ServiceKind, open_publish_subscribe};

/// Subscriber keeping the newest measured state.
pub struct StateTap {
    subscriber: Subscriber<ipc::Service, JointState, ()>,
    latest: Option<JointState>,
}

impl StateTap {
    /// Subscribes to `instance`'s state stream on `node`.
    pub fn open(node: &Node<ipc::Service>, instance: &str) -> anyhow::Result<Self> {
        let subscriber = open_publish_subscribe::<JointState>(node, instance, ServiceKind::State)?
            .subscriber_builder()
            .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow::anyhow!("state subscriber: {e:?}"))?;
        Ok(Self {
            subscriber,
            latest: None,
        })
    }

    /// Takes every waiting state, keeping the newest.
    pub fn poll(&mut self) {
        while let Ok(Some(s)) = self.subscriber.receive() {
            self.latest = Some(*s);
        }
    }

    /// The newest state seen.
    pub fn latest(&self) -> Option<&JointState> {
        self.latest.as_ref()
    }

    /// The environment entry for a restarted actuator (drain with [`StateTap::poll`]
    /// once the dead one is reaped, before its resources are cleaned).
    pub fn resume_env(&self) -> Option<(String, String)> {
        self.latest.as_ref().map(|s| {
            (
                microrobot_actuator::RESUME_ENV.to_string(),
                microrobot_actuator::resume::encode(s),
            )
        })
    }
}
