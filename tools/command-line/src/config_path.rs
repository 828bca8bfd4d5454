//! Where a command finds the pipeline config when `--config` is not given: `./config/
//! pipeline.toml` in the current directory, else the config that ships with the sources
//! this binary was built from, so `microrobot run` works from any directory.

use std::path::{Path, PathBuf};

/// The config path relative to a checkout.
const RELATIVE: &str = "config/pipeline.toml";

/// `./config/pipeline.toml` if it exists, else the shipped config (the source tree this
/// binary was built from) if that exists, else `config/pipeline.toml` (whose absence the
/// loader then reports by name).
pub fn default_config() -> PathBuf {
    let local = PathBuf::from(RELATIVE);
    if local.exists() {
        return local;
    }
    // This package is `tools/command-line` of the source tree.
    let source_tree = Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2);
    if let Some(shipped) = source_tree.map(|dir| dir.join(RELATIVE))
        && shipped.exists()
    {
        return shipped;
    }
    local
}
