//! The build id that every binary of the stack embeds (the CLI, the three service
//! binaries, `microrobot-view`): a hash of the sources they are built from (see
//! `build.rs`). The CLI refuses to start a binary whose id differs from its own.

/// This build's id, 16 hex digits.
pub const BUILD_ID: &str = env!("MICROROBOT_BUILD_ID");
