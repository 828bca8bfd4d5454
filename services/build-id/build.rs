//! Sets `MICROROBOT_BUILD_ID`: a hash of every source the workspace's binaries are built
//! from (the workspace manifest and lock file; the manifest and `src/` of `messages`, of
//! each crate in `services/` and of each crate in `tools/`; `services/bin/`;
//! `tools/src/`). The CLI, the three service binaries and `microrobot-view` embed it
//! (through this package's `BUILD_ID`), and the CLI refuses to start one whose id
//! differs from its own: one left over from an older build (e.g. after `cargo build
//! --bin microrobot` alone) never runs.
//!
//! The hash is FNV-1a over each file's path and bytes in a sorted walk; it only has to
//! tell builds apart, not resist an adversary.

use std::path::{Path, PathBuf};

fn main() {
    // This package is `services/build-id` of the workspace.
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest_dir
        .ancestors()
        .nth(2)
        .unwrap_or(&manifest_dir)
        .to_path_buf();
    let mut inputs: Vec<String> = [
        "Cargo.toml",
        "Cargo.lock",
        "messages/Cargo.toml",
        "messages/src",
        "services/bin",
        "tools/src",
    ]
    .map(String::from)
    .to_vec();
    for dir in ["services", "tools"] {
        let Ok(crates) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for entry in crates.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if entry.path().join("Cargo.toml").is_file() {
                inputs.push(format!("{dir}/{name}/Cargo.toml"));
                inputs.push(format!("{dir}/{name}/src"));
            }
        }
    }
    let mut files = Vec::new();
    for input in &inputs {
        println!("cargo::rerun-if-changed={}", root.join(input).display());
        collect(&root.join(input), &mut files);
    }
    files.sort();
    let mut hash = Fnv::default();
    for file in &files {
        let rel = file.strip_prefix(&root).unwrap_or(file);
        hash.write(rel.to_string_lossy().as_bytes());
        hash.write(&[0]);
        // A file that cannot be read still names itself; its bytes then count as none.
        hash.write(&std::fs::read(file).unwrap_or_default());
        hash.write(&[0]);
    }
    println!("cargo::rustc-env=MICROROBOT_BUILD_ID={:016x}", hash.0);
}

/// Every file under `path` (or `path` itself).
fn collect(path: &Path, files: &mut Vec<PathBuf>) {
    if path.is_file() {
        files.push(path.to_path_buf());
        return;
    }
    let Ok(entries) = std::fs::read_dir(path) else {
        return;
    };
    for entry in entries.flatten() {
        collect(&entry.path(), files);
    }
}

/// 64-bit FNV-1a.
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}
