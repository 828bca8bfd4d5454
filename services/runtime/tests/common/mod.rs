//! What the runner tests share.

use microrobot_runtime::config::PipelineConfig;

/// The default pipeline config for `instance`, without the real-time settings a test
/// process may not have (CPU pinning, PM QoS, SCHED_FIFO, `mlockall`).
pub fn plain_config(instance: &str) -> PipelineConfig {
    let mut cfg = PipelineConfig {
        instance: instance.into(),
        ..PipelineConfig::default()
    };
    cfg.realtime.cpu_affinity.clear();
    cfg.realtime.pm_qos = false;
    cfg.realtime.sched_fifo_priority = 0;
    cfg.realtime.mlockall = false;
    cfg
}
