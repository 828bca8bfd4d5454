//! The state directory (lock files, run directories with logs and the resolved config
//! that services load) is private to the user: `microrobot run` creates it 0700 with
//! owner-only files, and refuses one that is a symlink or belongs to someone else,
//! naming the path and the owner, without touching anything the symlinks in it point at.

use std::os::unix::fs::{MetadataExt, PermissionsExt, symlink};
use std::path::Path;
use std::process::{Command, Stdio};

use crate::common::*;

/// `microrobot run` of a short holding pipeline with `XDG_RUNTIME_DIR=xdg` (and no
/// `MICROROBOT_STATE_DIR`), so the state directory is `<xdg>/microrobot`.
fn run_with_runtime_dir(xdg: &Path, cfg: &Path) -> Finished {
    run_with_env(cfg, "XDG_RUNTIME_DIR", xdg, "MICROROBOT_STATE_DIR")
}

/// `microrobot run` of a short holding pipeline with `key=value` set and `unset` unset.
fn run_with_env(cfg: &Path, key: &str, value: &Path, unset: &str) -> Finished {
    let child = Command::new(bin())
        .args([
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--no-program",
        ])
        .args(["--duration", "1", "--quiet"])
        .env(key, value)
        .env_remove(unset)
        .current_dir(repo())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start microrobot");
    Proc::from_child(child).finish(120.0)
}

fn mode(p: &Path) -> u32 {
    std::fs::symlink_metadata(p).expect("stat").mode() & 0o7777
}

/// Every file under `dir` with its content and mtime, to show that nothing changed.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>, i64, u32)> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .expect("read_dir")
        .map(|e| {
            let p = e.expect("entry").path();
            let m = std::fs::symlink_metadata(&p).expect("stat");
            let data = std::fs::read(&p).unwrap_or_default();
            (
                p.display().to_string(),
                data,
                m.mtime_nsec() + m.mtime() * 1_000_000_000,
                m.mode(),
            )
        })
        .collect();
    out.sort();
    out
}

#[test]
fn run_creates_a_private_state_dir_with_owner_only_files() {
    let t = tempfile::tempdir().expect("tempdir");
    let xdg = t.path().join("xdg");
    std::fs::create_dir(&xdg).expect("mkdir");
    std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).expect("chmod");
    let inst = instance("statedir");
    let cfg = write_config(t.path(), &inst, "", "");
    let out = run_with_runtime_dir(&xdg, &cfg);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let state = xdg.join("microrobot");
    let run = state.join(&inst);
    assert_eq!(mode(&state), 0o700, "state dir");
    assert_eq!(mode(&run), 0o700, "run dir");
    let mut files = 0;
    for e in std::fs::read_dir(&run)
        .expect("run dir")
        .chain(std::fs::read_dir(&state).expect("state dir"))
    {
        let p = e.expect("entry").path();
        if p.is_dir() {
            continue;
        }
        assert_eq!(mode(&p), 0o600, "{}", p.display());
        files += 1;
    }
    // The lock, the resolved config and the three service logs at least.
    assert!(files >= 5, "{files} files");
    assert!(run.join("pipeline.resolved.toml").exists());
}

#[test]
fn run_refuses_a_state_dir_that_is_a_symlink() {
    let t = tempfile::tempdir().expect("tempdir");
    let xdg = t.path().join("xdg");
    let elsewhere = t.path().join("elsewhere");
    std::fs::create_dir(&xdg).expect("mkdir");
    std::fs::create_dir(&elsewhere).expect("mkdir");
    std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).expect("chmod");
    std::fs::write(elsewhere.join("keep"), "keep").expect("write");
    symlink(&elsewhere, xdg.join("microrobot")).expect("symlink");
    let inst = instance("statelink");
    let cfg = write_config(t.path(), &inst, "", "");
    let before = snapshot(&elsewhere);
    let out = run_with_runtime_dir(&xdg, &cfg);
    assert_ne!(out.code(), Some(0), "a symlinked state dir must be refused");
    let state = xdg.join("microrobot").display().to_string();
    assert!(
        out.stderr.contains(&state) && out.stderr.contains("is a symlink"),
        "{}",
        out.stderr
    );
    assert_eq!(
        snapshot(&elsewhere),
        before,
        "nothing changed where the link points"
    );
}

/// A state directory owned by another user (uid 65534; named by `MICROROBOT_STATE_DIR`,
/// which gets the same checks), with symlinks inside it where `run` writes its lock,
/// run directory and files: refused, nothing outside touched.
#[test]
fn run_refuses_a_state_dir_owned_by_another_user() {
    // SAFETY: geteuid cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: not root (chown to another uid needs root)");
        return;
    }
    let t = tempfile::tempdir().expect("tempdir");
    let outside = t.path().join("outside");
    std::fs::create_dir(&outside).expect("mkdir");
    let inst = instance("stateowner");
    let victim = outside.join("victim");
    std::fs::write(&victim, "do not overwrite").expect("write");
    let state = t.path().join("state");
    std::fs::create_dir(&state).expect("mkdir");
    std::fs::set_permissions(&state, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    symlink(&victim, state.join(format!("{inst}.lock"))).expect("symlink");
    symlink(&outside, state.join(&inst)).expect("symlink");
    std::os::unix::fs::lchown(state.join(format!("{inst}.lock")), Some(65534), Some(65534))
        .expect("lchown");
    std::os::unix::fs::lchown(state.join(&inst), Some(65534), Some(65534)).expect("lchown");
    std::os::unix::fs::chown(&state, Some(65534), Some(65534)).expect("chown");
    let cfg = write_config(t.path(), &inst, "", "");
    let before = snapshot(&outside);
    let out = run_with_env(&cfg, "MICROROBOT_STATE_DIR", &state, "XDG_RUNTIME_DIR");
    assert_ne!(
        out.code(),
        Some(0),
        "another user's state dir must be refused"
    );
    assert!(
        out.stderr.contains(&state.display().to_string())
            && out.stderr.contains("owned by uid 65534"),
        "the error names the path and the owner: {}",
        out.stderr
    );
    assert_eq!(snapshot(&outside), before, "nothing outside was touched");
    assert!(remaining_nodes(&inst).is_empty(), "no service was started");
}
