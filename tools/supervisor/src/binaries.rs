//! Where the CLI finds the binaries of its own build that it runs: the three real-time
//! service binaries (`microrobot-planner`, `microrobot-dynamics`, `microrobot-actuator`)
//! and the live view (`microrobot-view`, a package of its own): beside the `microrobot`
//! executable, and only if they come from the same build.
//!
//! Every binary of the `microrobot` package (and `microrobot-view`) embeds the build id
//! that the package `microrobot-build-id` (`services/build-id`) computes from the sources
//! (`microrobot-<role> --build-id` prints it). A service binary that is missing, or
//! whose id is not this CLI's, is a binary of another build: when this
//! process runs under `cargo run` (Cargo's environment for this package is set), Cargo is
//! asked to build them in the same profile and target directory, since `cargo run
//! --bin microrobot` builds only the CLI; otherwise it is an error that names the binary
//! and the command that builds them all. (Under `cargo test` the services are always of
//! the CLI's build: Cargo builds every binary of the package for the tests.)

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::Context as _;
use microrobot_messages::ServiceRole;

/// This build's id (see the module doc).
pub const BUILD_ID: &str = microrobot_build_id::BUILD_ID;

/// The roles that run as service binaries, in start order.
const ROLES: [ServiceRole; 3] = [
    ServiceRole::Actuator,
    ServiceRole::Dynamics,
    ServiceRole::Planner,
];

/// The service binaries of this build, all checked.
#[derive(Debug, Clone)]
pub struct ServiceBinaries {
    dir: PathBuf,
}

/// Binaries of this build that the CLI runs from its own directory, and how to build them.
struct Siblings {
    /// What they are, for messages ("the service binaries").
    what: &'static str,
    /// Their file names.
    names: Vec<String>,
    /// Cargo's selection of them (after `cargo build`).
    select: Vec<String>,
    /// Whether `cargo build` in the repository (no selection) builds them too.
    in_default_build: bool,
    /// How the error names the build ("build them all") and a copy ("copy ... together").
    build_phrase: &'static str,
    copy_phrase: &'static str,
}

impl Siblings {
    /// Finds and checks the binaries beside the running executable, building them first
    /// when this process runs under `cargo run` and they are missing or stale; returns
    /// their directory.
    fn locate(&self) -> anyhow::Result<PathBuf> {
        let exe = std::env::current_exe().context("cannot find the microrobot executable")?;
        let dir = exe
            .parent()
            .context("the microrobot executable has no directory")?
            .to_path_buf();
        let Err(stale) = self.check(&dir) else {
            return Ok(dir);
        };
        let Some(cargo) = CargoBuild::of_parent(&dir, &self.select) else {
            anyhow::bail!("{stale:#}: {}", self.how_to_build(&dir));
        };
        eprintln!(
            "microrobot: {stale:#}; building {}: {}",
            self.what,
            cargo.describe()
        );
        cargo.run(self.what)?;
        self.check(&dir)?;
        Ok(dir)
    }

    /// Each binary exists in `dir` and prints this build's id.
    fn check(&self, dir: &Path) -> anyhow::Result<()> {
        for name in &self.names {
            let path = dir.join(name);
            let id = build_id_of(&path)?;
            anyhow::ensure!(
                id == BUILD_ID,
                "{} is from another build (build id {id}; this microrobot is {BUILD_ID})",
                path.display()
            );
        }
        Ok(())
    }

    /// What to run to build them for the CLI in `dir`.
    fn how_to_build(&self, dir: &Path) -> String {
        let in_target = dir
            .parent()
            .is_some_and(|t| t.join("CACHEDIR.TAG").is_file());
        let profile = match dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") if in_target => String::new(),
            Some(p) if in_target && p != "release" => format!(" --profile {p}"),
            _ => " --release".to_string(),
        };
        let select = if self.in_default_build {
            String::new()
        } else {
            format!(" {}", self.select.join(" "))
        };
        format!(
            "{} must come from the same build, beside microrobot ({}): {} with \
             `cargo build{profile}{select}` in the repository{}",
            self.what,
            dir.display(),
            self.build_phrase,
            if in_target { "" } else { self.copy_phrase }
        )
    }
}

impl ServiceBinaries {
    fn siblings() -> Siblings {
        let names: Vec<String> = ROLES
            .iter()
            .map(|r| format!("microrobot-{}", r.name()))
            .collect();
        Siblings {
            what: "the service binaries",
            select: names
                .iter()
                .flat_map(|n| ["--bin".to_string(), n.clone()])
                .collect(),
            names,
            in_default_build: true,
            build_phrase: "build them all",
            copy_phrase: " and copy the four binaries together",
        }
    }

    /// Finds and checks the service binaries beside the running executable, building them
    /// first when this process runs under `cargo run` and they are missing or stale.
    pub fn locate() -> anyhow::Result<Self> {
        Ok(Self {
            dir: Self::siblings().locate()?,
        })
    }

    /// The binary that runs `role`.
    pub fn path(&self, role: ServiceRole) -> PathBuf {
        self.dir.join(format!("microrobot-{}", role.name()))
    }
}

/// The live-view binary `microrobot view` execs.
pub const VIEW_BINARY: &str = "microrobot-view";

/// Finds and checks `microrobot-view` (package `microrobot-view`, kept out of this
/// package so its WebSocket stack is no part of the CLI's build) beside the running
/// executable, as [`ServiceBinaries::locate`] does for the services: under `cargo run`
/// Cargo builds it first (`cargo build -p microrobot-view`, same profile and target
/// directory); otherwise a missing or stale one is an error naming that command.
pub fn locate_view() -> anyhow::Result<PathBuf> {
    let dir = Siblings {
        what: "the live view",
        names: vec![VIEW_BINARY.to_string()],
        select: vec!["-p".to_string(), VIEW_BINARY.to_string()],
        in_default_build: false,
        build_phrase: "build it",
        copy_phrase: " and copy it beside microrobot",
    }
    .locate()?;
    Ok(dir.join(VIEW_BINARY))
}

/// Finds and checks `microrobot-chain-link` (the bare chain's link, a slim binary of
/// the `microrobot` package) beside the running executable, as
/// [`ServiceBinaries::locate`] does for the services.
pub fn locate_chain_link() -> anyhow::Result<PathBuf> {
    let name = microrobot_chain_link::BINARY;
    let dir = Siblings {
        what: "the chain probe's link",
        names: vec![name.to_string()],
        select: vec!["--bin".to_string(), name.to_string()],
        in_default_build: true,
        build_phrase: "build it",
        copy_phrase: " and copy it beside microrobot",
    }
    .locate()?;
    Ok(dir.join(name))
}

/// The id `path --build-id` prints.
fn build_id_of(path: &Path) -> anyhow::Result<String> {
    anyhow::ensure!(path.is_file(), "{} is missing", path.display());
    let out = Command::new(path)
        .arg("--build-id")
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .output()
        .with_context(|| format!("cannot run {}", path.display()))?;
    anyhow::ensure!(
        out.status.success(),
        "{} --build-id failed ({}): not a service binary of this stack",
        path.display(),
        out.status
    );
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// `cargo build` of sibling binaries into the directory the CLI runs from.
struct CargoBuild {
    cargo: PathBuf,
    args: Vec<String>,
}

impl CargoBuild {
    /// The build to run when this process runs under Cargo for this package (`cargo
    /// run` execs it with `$CARGO`, `CARGO_PKG_NAME` and `CARGO_MANIFEST_PATH` set), with
    /// that manifest and the profile and target directory of `exe_dir`
    /// (`<target>/<profile>`); `None` otherwise.
    fn of_parent(exe_dir: &Path, select: &[String]) -> Option<Self> {
        let cargo = PathBuf::from(std::env::var_os("CARGO")?);
        let manifest = std::env::var_os("CARGO_MANIFEST_PATH")
            .map(PathBuf::from)
            .or_else(|| {
                std::env::var_os("CARGO_MANIFEST_DIR").map(|d| PathBuf::from(d).join("Cargo.toml"))
            })?;
        if std::env::var_os("CARGO_PKG_NAME")? != "microrobot" {
            return None; // started under Cargo for another package
        }
        let target_dir = exe_dir.parent()?;
        if !target_dir.join("CACHEDIR.TAG").is_file() {
            return None; // not `<target>/<profile>` (e.g. a `--target <triple>` build)
        }
        let mut args = vec![
            "build".to_string(),
            "--quiet".to_string(),
            "--manifest-path".to_string(),
            manifest.display().to_string(),
            "--target-dir".to_string(),
            target_dir.display().to_string(),
        ];
        match exe_dir.file_name()?.to_str()? {
            "debug" => {}
            "release" => args.push("--release".to_string()),
            p => args.extend(["--profile".to_string(), p.to_string()]),
        }
        args.extend_from_slice(select);
        Some(Self { cargo, args })
    }

    fn describe(&self) -> String {
        let args: Vec<&str> = self
            .args
            .iter()
            .map(String::as_str)
            .filter(|a| *a != "--quiet")
            .collect();
        format!("cargo {}", args.join(" "))
    }

    fn run(&self, what: &str) -> anyhow::Result<()> {
        let status = Command::new(&self.cargo)
            .args(&self.args)
            .stdin(Stdio::null())
            .status()
            .with_context(|| format!("cannot run {}", self.cargo.display()))?;
        anyhow::ensure!(
            status.success(),
            "building {what} failed ({status}): {}",
            self.describe()
        );
        Ok(())
    }
}
