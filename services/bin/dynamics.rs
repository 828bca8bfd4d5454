//! `microrobot-dynamics --config FILE`: the dynamics service, one of the three real-time
//! processes that `microrobot run` starts. It links only the service, the runtime, the
//! build id and the pipeline file's reader (`microrobot-config`, which checks every
//! section through the crate that owns it), so the process that runs (and locks into
//! memory) the cycle holds nothing else.

use std::process::ExitCode;

fn main() -> ExitCode {
    microrobot_runtime::service_binary_main(
        microrobot_runtime::ServiceRole::Dynamics,
        microrobot_build_id::BUILD_ID,
        microrobot_config::load,
        microrobot_dynamics::run,
    )
}
