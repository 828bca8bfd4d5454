//! One pipeline per instance name: an `flock`ed lock file refuses a second supervisor,
//! a scan of live iceoryx2 nodes refuses running next to orphaned services, and what a
//! crashed earlier run left behind (dead nodes, services nobody holds) is removed.
//!
//! Lock files and run directories (logs, the resolved config a restarted service loads)
//! live in a per-user state directory ([`state_dir`]) that only its owner can enter:
//! created 0700, used only if it is a real directory (not a symlink) of this user that
//! nobody else can write, and every file in it is opened without following symlinks,
//! owner-only (0600).

use std::ffi::OsString;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;
use microrobot_messages::{CONTRACT_VERSION, ServiceKind, service_name};

/// Where lock files and run directories live (not created here; see
/// [`private_dir`]): `$MICROROBOT_STATE_DIR` if set, else `$XDG_RUNTIME_DIR/microrobot`
/// when `$XDG_RUNTIME_DIR` is usable (an absolute path to a directory of this user that
/// nobody else can write), else `/tmp/microrobot-<uid>`.
pub fn state_dir() -> PathBuf {
    state_dir_for(
        std::env::var_os("MICROROBOT_STATE_DIR"),
        std::env::var_os("XDG_RUNTIME_DIR"),
        euid(),
    )
}

/// [`state_dir`] for the given environment values and effective uid.
pub fn state_dir_for(
    explicit: Option<OsString>,
    xdg_runtime: Option<OsString>,
    uid: u32,
) -> PathBuf {
    if let Some(dir) = explicit.filter(|d| !d.is_empty()) {
        return PathBuf::from(dir);
    }
    let usable = |d: &Path| {
        d.is_absolute()
            && std::fs::symlink_metadata(d)
                .is_ok_and(|m| m.is_dir() && m.uid() == uid && m.mode() & 0o022 == 0)
    };
    match xdg_runtime.map(PathBuf::from) {
        Some(d) if usable(&d) => d.join("microrobot"),
        _ => PathBuf::from(format!("/tmp/microrobot-{uid}")),
    }
}

/// The effective uid of this process.
pub fn euid() -> u32 {
    // SAFETY: geteuid cannot fail.
    unsafe { libc::geteuid() }
}

/// `uid 65534 (nobody)`: the uid and, when known, its user name.
pub fn describe_uid(uid: u32) -> String {
    let mut pw: libc::passwd = unsafe { std::mem::zeroed() };
    let mut buf = vec![0 as libc::c_char; 4096];
    let mut out: *mut libc::passwd = std::ptr::null_mut();
    // SAFETY: getpwuid_r writes into `pw` and `buf` (sizes given) and sets `out` to `&pw`
    // on success; `pw_name` then points into `buf`, alive for this scope.
    let rc = unsafe { libc::getpwuid_r(uid, &mut pw, buf.as_mut_ptr(), buf.len(), &mut out) };
    if rc == 0 && !out.is_null() && !pw.pw_name.is_null() {
        // SAFETY: a NUL-terminated string inside `buf`.
        let name = unsafe { std::ffi::CStr::from_ptr(pw.pw_name) };
        return format!("uid {uid} ({})", name.to_string_lossy());
    }
    format!("uid {uid}")
}

/// A directory that is not this user's private directory.
#[derive(Debug)]
pub struct NotPrivate {
    pub path: PathBuf,
    pub detail: String,
}

impl std::fmt::Display for NotPrivate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "refusing to use {}: it {}; it must be a directory (not a symlink) owned by {} that nobody else can write. Remove it, or set MICROROBOT_STATE_DIR to a directory of your own",
            self.path.display(),
            self.detail,
            describe_uid(euid())
        )
    }
}

impl std::error::Error for NotPrivate {}

/// Makes sure `path` is this user's private directory: creates it (and missing parents)
/// with mode 0700, then checks, on the opened directory itself, that it is a directory
/// and not a symlink, owned by the effective uid and not writable by group or others;
/// read or search bits for group or others are removed (0700). Anything else is a
/// [`NotPrivate`] error naming the path and its owner.
pub fn private_dir(path: &Path) -> anyhow::Result<()> {
    match std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(path)
    {
        Ok(()) => {}
        // An existing symlink or file is reported below, with what it is.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => anyhow::bail!("cannot create {}: {e}", path.display()),
    }
    check_private_dir(path)
}

/// Checks (without creating anything) that `path` is this user's private directory, as
/// [`private_dir`] does.
pub fn check_private_dir(path: &Path) -> anyhow::Result<()> {
    let not_private = |detail: String| NotPrivate {
        path: path.to_path_buf(),
        detail,
    };
    let dir = match OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
    {
        Ok(d) => d,
        Err(e) => {
            let meta = std::fs::symlink_metadata(path);
            if let Ok(m) = &meta
                && m.file_type().is_symlink()
            {
                let target = std::fs::read_link(path)
                    .map_or_else(|_| "?".to_string(), |t| t.display().to_string());
                return Err(not_private(format!(
                    "is a symlink (to {target}), owned by {}",
                    describe_uid(m.uid())
                ))
                .into());
            }
            if let Ok(m) = &meta
                && !m.is_dir()
            {
                return Err(not_private(format!(
                    "is not a directory, owned by {}",
                    describe_uid(m.uid())
                ))
                .into());
            }
            anyhow::bail!("cannot open {}: {e}", path.display());
        }
    };
    let m = dir
        .metadata()
        .map_err(|e| anyhow::anyhow!("cannot stat {}: {e}", path.display()))?;
    if m.uid() != euid() {
        return Err(not_private(format!("is owned by {}", describe_uid(m.uid()))).into());
    }
    let mode = m.mode() & 0o7777;
    if mode & 0o022 != 0 {
        return Err(
            not_private(format!("is writable by group or others (mode {mode:04o})")).into(),
        );
    }
    if mode & 0o077 != 0 {
        dir.set_permissions(std::fs::Permissions::from_mode(mode & 0o7700))
            .map_err(|e| anyhow::anyhow!("cannot make {} private (0700): {e}", path.display()))?;
    }
    Ok(())
}

/// Opens `path` for appending, owner-only (0600), creating it if missing and never
/// following a symlink (a symlink there is an error).
pub fn open_private_append(path: &Path) -> std::io::Result<File> {
    OpenOptions::new()
        .create(true)
        .append(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
}

/// Creates `path` as a new file, owner-only (0600), failing if anything (a file, a
/// symlink) is already there.
pub fn create_private_new(path: &Path) -> std::io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
}

/// Replaces `path` with `contents`, owner-only (0600): written to a fresh temporary file
/// next to it (created exclusively, symlinks not followed) and renamed over it, so a
/// symlink at `path` is replaced, never written through.
pub fn write_private(path: &Path, contents: &[u8]) -> anyhow::Result<()> {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".tmp.{}", std::process::id()));
    let tmp = path.with_file_name(name);
    let _ = std::fs::remove_file(&tmp);
    let result = create_private_new(&tmp)
        .and_then(|mut f| f.write_all(contents).and_then(|()| f.sync_all()))
        .and_then(|()| std::fs::rename(&tmp, path));
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        anyhow::bail!("cannot write {}: {e}", path.display());
    }
    Ok(())
}

/// The file `name` in the run directory of `instance`, after checking that the state
/// and run directories are this user's private directories (for readers of a run's
/// files; nothing is created).
pub fn run_file(instance: &str, name: &str) -> anyhow::Result<PathBuf> {
    let state = state_dir();
    check_private_dir(&state)?;
    let dir = state.join(instance);
    check_private_dir(&dir)?;
    Ok(dir.join(name))
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
    private_dir(&dir)?;
    let path = dir.join(format!("{instance}.lock"));
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
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

/// A fresh run directory for `instance` (`<state dir>/<instance>/`, private as the
/// state directory), emptied of a previous run's logs.
pub fn run_dir(instance: &str) -> anyhow::Result<PathBuf> {
    let state = state_dir();
    private_dir(&state)?;
    let dir = state.join(instance);
    private_dir(&dir)?;
    for name in [
        "planner.log",
        "dynamics.log",
        "actuator.log",
        "recorder.log",
    ] {
        // Removes a symlink itself, never its target.
        let _ = std::fs::remove_file(dir.join(name));
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode(p: &Path) -> u32 {
        std::fs::symlink_metadata(p).expect("stat").mode() & 0o7777
    }

    #[test]
    fn the_state_dir_is_per_user() {
        let t = tempfile::tempdir().expect("tempdir");
        let xdg = t.path().join("run-user");
        std::fs::create_dir(&xdg).expect("mkdir");
        std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).expect("chmod");
        let uid = euid();
        let fallback = PathBuf::from(format!("/tmp/microrobot-{uid}"));
        assert_eq!(
            state_dir_for(Some("/x/y".into()), Some(xdg.clone().into()), uid),
            PathBuf::from("/x/y")
        );
        assert_eq!(
            state_dir_for(None, Some(xdg.clone().into()), uid),
            xdg.join("microrobot")
        );
        assert_eq!(state_dir_for(None, None, uid), fallback);
        assert_eq!(state_dir_for(None, Some("run/user".into()), uid), fallback);
        assert_eq!(
            state_dir_for(None, Some(t.path().join("absent").into()), uid),
            fallback
        );
        // Someone else's runtime directory (as after `sudo`), or one others can write.
        assert_eq!(
            state_dir_for(None, Some(xdg.clone().into()), uid + 1),
            PathBuf::from(format!("/tmp/microrobot-{}", uid + 1))
        );
        std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o777)).expect("chmod");
        assert_eq!(state_dir_for(None, Some(xdg.into()), uid), fallback);
    }

    #[test]
    fn private_dirs_are_created_0700_and_checked() {
        let t = tempfile::tempdir().expect("tempdir");
        let d = t.path().join("a/b");
        private_dir(&d).expect("create");
        assert_eq!(mode(&d), 0o700);
        // Read bits for others are taken away; write bits for others are refused.
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        private_dir(&d).expect("tighten");
        assert_eq!(mode(&d), 0o700);
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o770)).expect("chmod");
        let e = private_dir(&d).expect_err("group-writable").to_string();
        assert!(e.contains("writable by group or others (mode 0770)"), "{e}");
        // A symlink, even to a private directory of ours, is refused.
        let link = t.path().join("link");
        std::os::unix::fs::symlink(t.path().join("a"), &link).expect("symlink");
        let e = private_dir(&link).expect_err("symlink").to_string();
        assert!(
            e.contains(&link.display().to_string()) && e.contains("is a symlink"),
            "{e}"
        );
        let file = t.path().join("file");
        std::fs::write(&file, "x").expect("write");
        let e = private_dir(&file).expect_err("file").to_string();
        assert!(e.contains("is not a directory"), "{e}");
    }

    #[test]
    fn private_files_never_follow_symlinks() {
        let t = tempfile::tempdir().expect("tempdir");
        let victim = t.path().join("victim");
        std::fs::write(&victim, "keep").expect("write");
        let link = t.path().join("pipeline.resolved.toml");
        std::os::unix::fs::symlink(&victim, &link).expect("symlink");
        // Replaced, not written through.
        write_private(&link, b"new").expect("write_private");
        assert_eq!(std::fs::read_to_string(&victim).expect("read"), "keep");
        assert_eq!(std::fs::read_to_string(&link).expect("read"), "new");
        assert_eq!(mode(&link), 0o600);
        let log = t.path().join("planner.log");
        std::os::unix::fs::symlink(&victim, &log).expect("symlink");
        assert!(open_private_append(&log).is_err());
        assert!(create_private_new(&log).is_err());
        assert_eq!(std::fs::read_to_string(&victim).expect("read"), "keep");
        let fresh = t.path().join("fresh.log");
        drop(open_private_append(&fresh).expect("append"));
        assert_eq!(mode(&fresh), 0o600);
    }
}
