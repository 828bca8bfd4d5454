//! Where the supervisor finds the three real-time service binaries (`microrobot-planner`,
//! `microrobot-dynamics`, `microrobot-actuator`): beside the `microrobot` executable, and
//! only if they come from the same build.
//!
//! Every binary of the `microrobot` package embeds the build id that `tools/build.rs`
//! computes from the sources (`microrobot-<role> --build-id` prints it). A service binary
//! that is missing, or whose id is not this CLI's, is a binary of another build: when this
//! process runs under `cargo run` (Cargo's environment for this package is set), Cargo is
//! asked to build the services in the same profile and target directory, since `cargo run
//! --bin microrobot` builds only the CLI; otherwise it is an error that names the binary
//! and the command that builds them all. (Under `cargo test` the services are always of
//! the CLI's build: Cargo builds every binary of the package for the tests.)

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::Context as _;
use microrobot_messages::ServiceRole;

/// This build's id (see the module doc).
pub const BUILD_ID: &str = env!("MICROROBOT_BUILD_ID");

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

impl ServiceBinaries {
    /// Finds and checks the service binaries beside the running executable, building them
    /// first when this process runs under `cargo run` and they are missing or stale.
    pub fn locate() -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot find the microrobot executable")?;
        let dir = exe
            .parent()
            .context("the microrobot executable has no directory")?
            .to_path_buf();
        let found = Self { dir };
        let Err(stale) = found.check() else {
            return Ok(found);
        };
        let Some(cargo) = CargoBuild::of_parent(&found.dir) else {
            anyhow::bail!("{stale:#}: {}", found.how_to_build());
        };
        eprintln!(
            "microrobot: {stale:#}; building the service binaries: {}",
            cargo.describe()
        );
        cargo.run()?;
        found.check()?;
        Ok(found)
    }

    /// The binary that runs `role`.
    pub fn path(&self, role: ServiceRole) -> PathBuf {
        self.dir.join(format!("microrobot-{}", role.name()))
    }

    /// Each binary exists and prints this build's id.
    fn check(&self) -> anyhow::Result<()> {
        for role in ROLES {
            let path = self.path(role);
            let id = build_id_of(&path)?;
            anyhow::ensure!(
                id == BUILD_ID,
                "{} is from another build (build id {id}; this microrobot is {BUILD_ID})",
                path.display()
            );
        }
        Ok(())
    }

    /// What to run to build every binary of this build.
    fn how_to_build(&self) -> String {
        let in_target = self
            .dir
            .parent()
            .is_some_and(|t| t.join("CACHEDIR.TAG").is_file());
        let cmd = match self.dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") if in_target => "cargo build".to_string(),
            Some(p) if in_target && p != "release" => format!("cargo build --profile {p}"),
            _ => "cargo build --release".to_string(),
        };
        format!(
            "the services run as binaries of the same build beside microrobot ({}): build them \
             all with `{cmd}` in the repository{}",
            self.dir.display(),
            if in_target {
                ""
            } else {
                " and copy the four binaries together"
            }
        )
    }
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

/// `cargo build` of the three service binaries into the directory the CLI runs from.
struct CargoBuild {
    cargo: PathBuf,
    args: Vec<String>,
}

impl CargoBuild {
    /// The build to run when this process runs under Cargo for this package (`cargo
    /// run` execs it with `$CARGO`, `CARGO_PKG_NAME` and `CARGO_MANIFEST_PATH` set), with
    /// that manifest and the profile and target directory of `exe_dir`
    /// (`<target>/<profile>`); `None` otherwise.
    fn of_parent(exe_dir: &Path) -> Option<Self> {
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
        for role in ROLES {
            args.extend(["--bin".to_string(), format!("microrobot-{}", role.name())]);
        }
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

    fn run(&self) -> anyhow::Result<()> {
        let status = Command::new(&self.cargo)
            .args(&self.args)
            .stdin(Stdio::null())
            .status()
            .with_context(|| format!("cannot run {}", self.cargo.display()))?;
        anyhow::ensure!(
            status.success(),
            "building the service binaries failed ({status}): {}",
            self.describe()
        );
        Ok(())
    }
}
