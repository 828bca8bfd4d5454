//! What the soak does to the pipeline: motion commands (a repeating cycle of moves, or
//! random valid moves and stops) through the same command service `microrobot send`
//! uses, resets after a fault, and CPU load threads.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use microrobot_messages::{
    CommandKind, MAX_JOINTS, MotionCommand, ProfileKind, ServiceKind, TargetSpace, monotonic_ns,
    open_event, open_publish_subscribe,
};
use microrobot_model::Robot;

/// SplitMix64: a small seeded generator (reproducible command sequences).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.unit()
    }
}

/// Joint targets the soak moves between: within the middle half of every joint's range.
#[derive(Debug, Clone)]
pub struct Targets {
    dof: usize,
    mid: [f64; MAX_JOINTS],
    half: [f64; MAX_JOINTS],
    next: usize,
}

impl Targets {
    pub fn new(robot: &Robot) -> Self {
        let mut t = Self {
            dof: robot.dof().min(MAX_JOINTS),
            mid: [0.0; MAX_JOINTS],
            half: [0.0; MAX_JOINTS],
            next: 0,
        };
        for (i, j) in robot.joints().iter().take(MAX_JOINTS).enumerate() {
            t.mid[i] = 0.5 * (j.limits.min + j.limits.max);
            t.half[i] = 0.25 * (j.limits.max - j.limits.min);
        }
        t
    }

    /// The next of a fixed cycle of four poses (alternating signs per joint).
    pub fn cycle(&mut self) -> [f64; MAX_JOINTS] {
        let k = self.next;
        self.next = (self.next + 1) % 4;
        let mut q = [0.0; MAX_JOINTS];
        for (i, qi) in q.iter_mut().enumerate().take(self.dof) {
            let s = match (k + i) % 4 {
                0 => 1.0,
                1 => 0.0,
                2 => -1.0,
                _ => 0.5,
            };
            *qi = self.mid[i] + s * self.half[i];
        }
        q
    }

    /// A uniformly random pose in the middle half of every range.
    pub fn random(&self, rng: &mut Rng) -> [f64; MAX_JOINTS] {
        let mut q = [0.0; MAX_JOINTS];
        for (i, qi) in q.iter_mut().enumerate().take(self.dof) {
            *qi = self.mid[i] + rng.range(-1.0, 1.0) * self.half[i];
        }
        q
    }

    pub fn dof(&self) -> usize {
        self.dof
    }
}

/// The command port: a publisher + notifier on the instance's command service.
pub struct CommandPort {
    _node: Node<ipc::Service>,
    publisher: Publisher<ipc::Service, MotionCommand, ()>,
    notifier: Notifier<ipc::Service>,
    seq: u64,
    pub sent: u64,
}

impl CommandPort {
    pub fn open(instance: &str) -> anyhow::Result<Self> {
        let node_name = format!("microrobot-soak.{instance}");
        let node = microrobot_runtime::node::named_node(&node_name)?;
        let publisher =
            open_publish_subscribe::<MotionCommand>(&node, instance, ServiceKind::Command)?
                .publisher_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("command publisher: {e:?}"))?;
        let notifier = open_event(&node, instance, ServiceKind::Command)?
            .notifier_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("command notifier: {e:?}"))?;
        Ok(Self {
            _node: node,
            publisher,
            notifier,
            seq: 0,
            sent: 0,
        })
    }

    fn send(&mut self, mut cmd: MotionCommand) {
        self.seq += 1;
        cmd.seq = self.seq;
        cmd.stamp_ns = monotonic_ns();
        if self.publisher.send_copy(cmd).is_ok() {
            self.sent += 1;
        }
        let _ = self.notifier.notify();
    }

    /// A time-optimal jerk-limited move to `target` at `limit_scale` of the limits.
    pub fn move_to(&mut self, target: &[f64; MAX_JOINTS], dof: usize, limit_scale: f64) {
        self.send(MotionCommand {
            kind: CommandKind::Move as u32,
            profile: ProfileKind::Soft as u32,
            space: TargetSpace::Joint as u32,
            dof: dof as u32,
            target: *target,
            duration_s: 0.0,
            limit_scale,
            ..Default::default()
        });
    }

    pub fn stop(&mut self) {
        self.send(MotionCommand {
            kind: CommandKind::Stop as u32,
            ..Default::default()
        });
    }

    pub fn reset(&mut self) {
        self.send(MotionCommand {
            kind: CommandKind::Reset as u32,
            ..Default::default()
        });
    }
}

/// `n` busy threads (normal priority, not pinned) until dropped.
pub struct CpuLoad {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl CpuLoad {
    pub fn start(n: usize) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let threads = (0..n)
            .filter_map(|k| {
                let s = stop.clone();
                std::thread::Builder::new()
                    .name(format!("soak-load-{k}"))
                    .spawn(move || {
                        let mut x = 1u64;
                        while !s.load(Ordering::Relaxed) {
                            for _ in 0..10_000 {
                                x = std::hint::black_box(
                                    x.wrapping_mul(6364136223846793005).wrapping_add(1),
                                );
                            }
                        }
                    })
                    .ok()
            })
            .collect();
        Self { stop, threads }
    }
}

impl Drop for CpuLoad {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generator_is_reproducible_and_uniform_enough() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        let xs: Vec<f64> = (0..1000).map(|_| a.unit()).collect();
        let ys: Vec<f64> = (0..1000).map(|_| b.unit()).collect();
        assert_eq!(xs, ys);
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.05, "{mean}");
    }
}
