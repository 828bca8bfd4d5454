//! iceoryx2 nodes and WaitSets for a service: signal handling disabled (one owner, see
//! [`crate::shutdown`]), dead nodes of crashed predecessors cleaned, and a second
//! process of the same role in the same instance refused.

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use microrobot_messages::ServiceRole;

/// A live process already runs this role in this instance.
#[derive(Debug, thiserror::Error)]
#[error(
    "instance `{instance}` is already in use: a live {role} (pid {pid}) runs it; stop it or pick another --instance"
)]
pub struct InstanceInUse {
    pub instance: String,
    pub role: &'static str,
    pub pid: i32,
}

/// The node name of `role` in `instance`.
pub fn node_name(instance: &str, role: &str) -> String {
    format!("microrobot.{instance}.{role}")
}

/// Creates the node of `role` in `instance` after checking that no live node of the same
/// name exists (the check is what refuses a second pipeline with the same instance).
/// Dead nodes (a `kill -9`ed predecessor) are cleaned on creation.
pub fn open_node(instance: &str, role: ServiceRole) -> anyhow::Result<Node<ipc::Service>> {
    open_named_node(instance, role.name())
}

/// [`open_node`] for any role name (drivers, tools).
pub fn open_named_node(instance: &str, role: &'static str) -> anyhow::Result<Node<ipc::Service>> {
    let name = node_name(instance, role);
    let cfg = Config::global_config();
    let mut found: Option<i32> = None;
    let me = std::process::id() as i32;
    let _ = Node::<ipc::Service>::list(cfg, |state| {
        match state {
            NodeState::Alive(view) => {
                if let Some(d) = view.details()
                    && d.name().as_str() == name
                    && d.process_id().value() != me
                {
                    found = Some(d.process_id().value());
                    return CallbackProgression::Stop;
                }
            }
            NodeState::Dead(view) => {
                let _ = view.try_remove_stale_resources();
            }
            _ => {}
        }
        CallbackProgression::Continue
    });
    if let Some(pid) = found {
        return Err(InstanceInUse {
            instance: instance.to_string(),
            role,
            pid,
        }
        .into());
    }
    named_node(&name)
}

/// A node named `name` with iceoryx2's signal handling disabled, without the
/// one-per-instance check of [`open_node`]: for tools (recorder, monitors, stand-ins)
/// that may run several at a time.
pub fn named_node(name: &str) -> anyhow::Result<Node<ipc::Service>> {
    let node_name: NodeName = name
        .try_into()
        .map_err(|e| anyhow::anyhow!("invalid node name `{name}`: {e:?}"))?;
    NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create iceoryx2 node `{name}`: {e:?}"))
}

/// A WaitSet with iceoryx2's signal handling disabled.
pub fn waitset() -> anyhow::Result<WaitSet<ipc::Service>> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create WaitSet: {e:?}"))
}
