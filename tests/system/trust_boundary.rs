//! Trust boundary: while a pipeline runs, every iceoryx2 file of this user — the shared
//! memory in /dev/shm (`iox2_*`) and the files, sockets and locks under /tmp/iceoryx2 —
//! is owner-only (no group or other bits), and the directories give others nothing.
//! The one exception is iceoryx2's own 16-byte global management segment
//! (`*.global_mgmt`), world-writable by iceoryx2's design and carrying no pipeline data.

use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::path::Path;

use crate::common::*;

fn walk(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, out);
        }
        out.push(p);
    }
}

#[test]
fn the_shared_memory_files_of_a_running_pipeline_are_owner_only() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("trust");
    let cfg = write_config(dir.path(), &inst, "", "");
    let proc = start_holding(&inst, &cfg, 60, None);
    // SAFETY: getuid has no preconditions.
    let uid = unsafe { libc::getuid() };
    let mut paths = Vec::new();
    walk(Path::new("/tmp/iceoryx2"), &mut paths);
    if let Ok(rd) = std::fs::read_dir("/dev/shm") {
        paths.extend(rd.flatten().map(|e| e.path()).filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("iox2_"))
        }));
    }
    let mut checked = 0;
    let mut open = Vec::new();
    for p in &paths {
        let Ok(m) = std::fs::symlink_metadata(p) else {
            continue; // removed meanwhile (another test's pipeline)
        };
        if m.uid() != uid || p.to_string_lossy().ends_with(".global_mgmt") {
            continue;
        }
        let mode = m.permissions().mode() & 0o777;
        // Files: nothing for group and others. Directories: others nothing, the group
        // at most list/enter (iceoryx2 0.10 creates them 0750).
        let forbidden = if m.is_dir() { 0o027 } else { 0o077 };
        if mode & forbidden != 0 {
            open.push(format!("{:o} {}", mode, p.display()));
        }
        checked += 1;
    }
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    assert!(checked > 20, "only {checked} iceoryx2 files found");
    assert!(open.is_empty(), "not owner-only:\n{}", open.join("\n"));
}
