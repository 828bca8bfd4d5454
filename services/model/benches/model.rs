//! Criterion benchmarks of the hot-path algorithms on the seed arm
//! (`config/robots/seed-arm.toml`, `model/*`) and the Panda from URDF
//! (`tests/reference/urdf/panda.toml`, `model/panda/*`) at random states inside
//! their limits.
//! Run: `cargo bench -p microrobot-model --bench model`.
//!
//! Time is the benchmark thread's own CPU time (Linux
//! `CLOCK_THREAD_CPUTIME_ID`), so time the shared 2-core machine spends on
//! other processes is not charged to the model; set `MICROROBOT_BENCH_WALL=1`
//! for criterion's wall clock instead.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{Criterion, Throughput, criterion_main};
use microrobot_model::{
    JointVector, ModelData, Robot, forward_dynamics, forward_kinematics, jacobian, lagrange_euler,
    mass_matrix, rnea,
};
use std::hint::black_box;

#[path = "../examples/common/mod.rs"]
mod common;

const STATES: usize = 64;

struct State {
    q: JointVector,
    qd: JointVector,
    qdd: JointVector,
}

fn states(robot: &Robot) -> Vec<State> {
    common::random_states(robot, STATES)
        .into_iter()
        .map(|[q, qd, qdd]| State { q, qd, qdd })
        .collect()
}

/// Thread CPU time in nanoseconds (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`).
struct ThreadCpuTime;

#[repr(C)]
struct Timespec {
    tv_sec: i64,
    tv_nsec: i64,
}

unsafe extern "C" {
    // From the C library that std already links; Linux x86_64/aarch64 layout.
    fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
}

const CLOCK_THREAD_CPUTIME_ID: i32 = 3;

fn thread_cpu_ns() -> u64 {
    let mut ts = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

struct NanosFormatter;

impl ValueFormatter for NanosFormatter {
    fn scale_values(&self, typical: f64, values: &mut [f64]) -> &'static str {
        if typical < 1e3 {
            "ns"
        } else {
            values.iter_mut().for_each(|v| *v /= 1e3);
            "µs"
        }
    }
    fn scale_throughputs(
        &self,
        _typical: f64,
        _throughput: &Throughput,
        _values: &mut [f64],
    ) -> &'static str {
        "(no throughput)"
    }
    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        thread_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &NanosFormatter
    }
}

fn benches<M: Measurement + 'static>(c: &mut Criterion<M>) {
    bench_robot(c, "model", &common::seed_arm(), true);
    bench_robot(c, "model/panda", &common::panda(), false);
}

/// `{prefix}/fk`, `/jacobian`, `/rnea`, `/mass_matrix`, `/forward_dynamics` (and
/// `/lagrange_euler` if asked) on `robot` at its 64 random states.
fn bench_robot<M: Measurement + 'static>(
    c: &mut Criterion<M>,
    prefix: &str,
    robot: &Robot,
    lagrange: bool,
) {
    let mut data = ModelData::new(robot);
    let st = states(robot);
    let mut k = 0usize;
    let mut next = || {
        k = (k + 1) % STATES;
        &st[k]
    };
    c.bench_function(&format!("{prefix}/fk"), |b| {
        b.iter(|| {
            let s = next();
            forward_kinematics(robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function(&format!("{prefix}/jacobian"), |b| {
        b.iter(|| {
            let s = next();
            jacobian(robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function(&format!("{prefix}/rnea"), |b| {
        b.iter(|| {
            let s = next();
            rnea(
                robot,
                &mut data,
                black_box(&s.q),
                black_box(&s.qd),
                black_box(&s.qdd),
            )
        })
    });
    c.bench_function(&format!("{prefix}/mass_matrix"), |b| {
        b.iter(|| {
            let s = next();
            mass_matrix(robot, &mut data, black_box(&s.q))
        })
    });
    c.bench_function(&format!("{prefix}/forward_dynamics"), |b| {
        b.iter(|| {
            let s = next();
            forward_dynamics(
                robot,
                &mut data,
                black_box(&s.q),
                black_box(&s.qd),
                black_box(&s.qdd),
            )
        })
    });
    if lagrange {
        c.bench_function(&format!("{prefix}/lagrange_euler"), |b| {
            b.iter(|| {
                let s = next();
                lagrange_euler::torque(robot, black_box(&s.q), black_box(&s.qd), black_box(&s.qdd))
            })
        });
    }
}

fn model() {
    if std::env::var_os("MICROROBOT_BENCH_WALL").is_some() {
        let mut c = Criterion::default()
            .with_measurement(WallTime)
            .configure_from_args();
        benches(&mut c);
        c.final_summary();
    } else {
        let mut c = Criterion::default()
            .with_measurement(ThreadCpuTime)
            .configure_from_args();
        benches(&mut c);
        c.final_summary();
    }
}

criterion_main!(model);
