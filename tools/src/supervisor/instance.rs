//! One pipeline per instance name: an `flock`ed lock file refuses a second supervisor,
//! a scan of live iceoryx2 nodes refuses running next to orphaned services, and what a
//! crashed earlier run left behind (dead nodes, services nobody holds) is removed.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::PathBuf;

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;
use microrobot_messages::{CONTRACT_VERSION, ServiceKind, service_name};

/// Where lock files and run directories live.
pub fn state_dir() -> PathBuf {
    std::env::var_os("MICROROBOT_STATE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/tmp/microrobot"))
}

/// The iceoryx2 node-name prefix of every process of `instance` (see `microrobot_runtime::node`).
pub fn node_prefix(instance: &str) -> String {
    format!("microrobot.{instance}.")
}

/// The service-name prefix of `instance`.
pub fn service_prefix(instance: &str) -> String {
    let status = service_name(instance, ServiceKind::Status);
    let cut = status.len() - ServiceKind::Status.stream_name().len();
    debug_assert!(status.starts_with(&format!("microrobot/v{CONTRACT_VERSION}/")));
    status[..cut].to_string()
}

/// Another process runs this instance.
#[derive(Debug)]
pub struct InstanceInUse {
    pub instance: String,
    pub detail: String,
}

impl std::fmt::Display for InstanceInUse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "instance `{}` is already in use: {}; stop it or pick another --instance",
            self.instance, self.detail
        )
    }
}

impl std::error::Error for InstanceInUse {}

/// An exclusive, process-lifetime lock on an instance name (released when dropped or
/// when the process dies, however it dies).
#[derive(Debug)]
pub struct InstanceLock {
    _file: File,
    pub path: PathBuf,
}

/// Takes the lock of `instance`, or says who holds it.
pub fn lock_instance(instance: &str) -> anyhow::Result<InstanceLock> {
    let dir = state_dir();
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let path = dir.join(format!("{instance}.lock"));
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .open(&path)
        .map_err(|e| anyhow::anyhow!("cannot open lock file {}: {e}", path.display()))?;
    // SAFETY: flock on a valid, owned fd.
    let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if rc != 0 {
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        let holder = holder.trim();
        return Err(InstanceInUse {
            instance: instance.to_string(),
            detail: if holder.is_empty() {
                format!("another `microrobot run` holds {}", path.display())
            } else {
                format!("`microrobot run` pid {holder} holds {}", path.display())
            },
        }
        .into());
    }
    let _ = file.set_len(0);
    let _ = file.seek(SeekFrom::Start(0));
    let _ = writeln!(file, "{}", std::process::id());
    Ok(InstanceLock { _file: file, path })
}

/// Live iceoryx2 nodes of `instance` other than this process: (node name, pid).
pub fn live_nodes(instance: &str) -> Vec<(String, i32)> {
    let prefix = node_prefix(instance);
    let me = std::process::id() as i32;
    let mut found = Vec::new();
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Alive(view) = state
            && let Some(d) = view.details()
            && d.name().as_str().starts_with(&prefix)
            && d.process_id().value() != me
        {
            found.push((d.name().as_str().to_string(), d.process_id().value()));
        }
        CallbackProgression::Continue
    });
    found
}

/// What [`clean_leftovers`] removed.
#[derive(Debug, Default, Clone, Copy)]
pub struct Cleanup {
    /// Dead nodes (of any instance) whose stale resources were removed.
    pub dead_nodes: usize,
    /// Services of this instance that no live node held any more.
    pub orphaned_services: usize,
}

/// Removes the resources of dead nodes and the services of `instance` that no live
/// node holds (what a `kill -9`ed earlier run leaves in /dev/shm and the iceoryx2 root).
pub fn clean_leftovers(instance: &str) -> Cleanup {
    let mut out = Cleanup::default();
    let cfg = Config::global_config();
    let _ = Node::<ipc::Service>::list(cfg, |state| {
        if let NodeState::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            out.dead_nodes += 1;
        }
        CallbackProgression::Continue
    });
    let orphans = services_of(instance, true);
    if orphans.is_empty() {
        return out;
    }
    let Ok(node) = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
    else {
        return out;
    };
    for (name, pattern) in orphans {
        let Ok(svc_name) = ServiceName::new(&name) else {
            continue;
        };
        // SAFETY: no live node holds this service (checked in `services_of`), and the
        // instance lock keeps a new pipeline of this instance from starting meanwhile.
        if let Ok(true) = unsafe { node.force_remove_service(&svc_name, pattern) } {
            out.orphaned_services += 1;
        }
    }
    out
}

/// Services of `instance` (name, pattern); with `orphaned_only`, only those that no live
/// node is attached to.
pub fn services_of(instance: &str, orphaned_only: bool) -> Vec<(String, MessagingPattern)> {
    let prefix = service_prefix(instance);
    let mut found = Vec::new();
    let _ = <ipc::Service as iceoryx2::service::Service>::list(Config::global_config(), |d| {
        let name = d.static_details.name().as_str().to_string();
        if !name.starts_with(&prefix) {
            return CallbackProgression::Continue;
        }
        let pattern = match d.static_details.messaging_pattern() {
            StaticPattern::PublishSubscribe(_) => MessagingPattern::PublishSubscribe,
            StaticPattern::Event(_) => MessagingPattern::Event,
            _ => return CallbackProgression::Continue,
        };
        let held = d
            .dynamic_details
            .as_ref()
            .is_some_and(|dd| dd.nodes.iter().any(|n| matches!(n, NodeState::Alive(_))));
        if !orphaned_only || !held {
            found.push((name, pattern));
        }
        CallbackProgression::Continue
    });
    found
}

/// A fresh run directory for `instance` (`<state dir>/<instance>/`), emptied of a
/// previous run's logs.
pub fn run_dir(instance: &str) -> anyhow::Result<PathBuf> {
    let dir = state_dir().join(instance);
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("cannot create run dir {}: {e}", dir.display()))?;
    for name in ["planner.log", "dynamics.log", "actuator.log"] {
        let _ = std::fs::remove_file(dir.join(name));
    }
    Ok(dir)
}
