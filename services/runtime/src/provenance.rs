//! Where a bus message comes from: the process behind an iceoryx2 publisher, and
//! whether this pipeline's supervisor started it.
//!
//! A cyclic stream follows one publisher ([`crate::validate::StreamOwner`]); when that
//! one falls silent (a stall, a kill), the next one takes the stream over. Silence alone
//! must not hand the torque stream to any local process: a stage under a supervisor
//! takes a stream only from the supervisor's own processes — the supervisor itself or a
//! child of it, the pid [`SUPERVISOR_ENV`] names. The publisher's node says which process
//! created it (iceoryx2's node details); its parent comes from the kernel
//! (`/proc/<pid>/stat`). A stage started by hand (no supervisor) keeps the plain rule.
//!
//! What this does not defend: a process of the same user that forges iceoryx2's node
//! details (claiming the pid of the pipeline's own, stopped, service) or that ptraces the
//! pipeline; the README's "Trust boundary" says so.

use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::*;
use iceoryx2::service::ipc;
use iceoryx2::service::port_factory::publish_subscribe;

/// The environment variable in which the supervisor hands its pid to its children.
pub const SUPERVISOR_ENV: &str = "MICROROBOT_SUPERVISOR_PID";

/// Where a publisher comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// The supervisor or one of its children (or any process, for a stage not started
    /// by a supervisor).
    Pipeline,
    /// Another process, with its pid.
    Outsider(i32),
    /// Not found (the publisher left before it could be looked up): refused, not cached.
    Unknown,
}

/// Checks publishers against the supervisor; remembers the last verdicts, so a stream's
/// publisher is looked up once, not per message.
#[derive(Debug)]
pub struct Provenance {
    supervisor: Option<i32>,
    cache: [(u128, Origin); 8],
    next: usize,
}

impl Provenance {
    /// The check for a process whose supervisor pid is in [`SUPERVISOR_ENV`] (none: every
    /// publisher counts as the pipeline's).
    pub fn from_env() -> Self {
        let supervisor = std::env::var(SUPERVISOR_ENV)
            .ok()
            .and_then(|v| v.trim().parse::<i32>().ok())
            .filter(|p| *p > 0);
        Self::new(supervisor)
    }

    /// The check against supervisor `supervisor`.
    pub fn new(supervisor: Option<i32>) -> Self {
        Self {
            supervisor,
            cache: [(0, Origin::Unknown); 8],
            next: 0,
        }
    }

    /// The supervisor checked against, if any.
    pub fn supervisor(&self) -> Option<i32> {
        self.supervisor
    }

    /// Where `publisher` (an iceoryx2 `UniquePublisherId` value) of service `svc` comes
    /// from. Looks up iceoryx2's node list and `/proc` the first time a publisher is seen
    /// (once per publisher: a restart, an intruder), so call it only for a publisher the
    /// stream does not follow yet.
    pub fn check<T>(
        &mut self,
        svc: &publish_subscribe::PortFactory<ipc::Service, T, ()>,
        publisher: u128,
    ) -> Origin
    where
        T: std::fmt::Debug + ZeroCopySend + 'static,
    {
        let Some(supervisor) = self.supervisor else {
            return Origin::Pipeline;
        };
        if let Some((_, o)) = self
            .cache
            .iter()
            .find(|(p, o)| *p == publisher && *o != Origin::Unknown)
        {
            return *o;
        }
        let origin = match publisher_pid(svc, publisher) {
            None => Origin::Unknown,
            Some(pid) if pid == supervisor || parent_of(pid) == Some(supervisor) => {
                Origin::Pipeline
            }
            Some(pid) => Origin::Outsider(pid),
        };
        if origin != Origin::Unknown {
            self.cache[self.next] = (publisher, origin);
            self.next = (self.next + 1) % self.cache.len();
        }
        origin
    }
}

/// The pid of the process whose node created `publisher` (an iceoryx2
/// `UniquePublisherId` value) of `svc`; `None` once the publisher or its node is gone.
pub fn publisher_pid<T>(
    svc: &publish_subscribe::PortFactory<ipc::Service, T, ()>,
    publisher: u128,
) -> Option<i32>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let mut node_id = None;
    svc.dynamic_config().list_publishers(|d| {
        if d.publisher_id.value() == publisher {
            node_id = Some(d.node_id);
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    let node_id = node_id?;
    let mut pid = None;
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Alive(view) = &state
            && *view.id() == node_id
        {
            pid = view.details().as_ref().map(|d| d.process_id().value());
            return CallbackProgression::Stop;
        }
        CallbackProgression::Continue
    });
    pid
}

/// The parent pid of `pid`, from `/proc/<pid>/stat` (the field after the state, past the
/// parenthesised command name, which may itself contain spaces and parentheses).
pub fn parent_of(pid: i32) -> Option<i32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    parse_ppid(&stat)
}

fn parse_ppid(stat: &str) -> Option<i32> {
    let after = &stat[stat.rfind(')')? + 1..];
    after.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parent_is_read_past_a_command_name_with_spaces_and_parentheses() {
        assert_eq!(parse_ppid("1234 (a (b) c) S 99 1234 1234 0 -1"), Some(99));
        assert_eq!(parse_ppid("1 (init) S 0 1 1"), Some(0));
        assert_eq!(parse_ppid("garbage"), None);
        // This process's parent, as the kernel says.
        let me = std::process::id() as i32;
        assert_eq!(
            parent_of(me),
            Some(std::os::unix::process::parent_id() as i32)
        );
    }

    #[test]
    fn without_a_supervisor_every_publisher_is_the_pipelines() {
        let p = Provenance::new(None);
        assert_eq!(p.supervisor(), None);
    }
}
