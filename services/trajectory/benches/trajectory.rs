//! Criterion benchmarks: planning 6 joints (rest to rest, from a moving state) and
//! sampling 6 joints. Run: `cargo bench -p microrobot-trajectory --bench trajectory`.

// Joint loops index several per-joint vectors in step.
#![allow(clippy::needless_range_loop)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use microrobot_trajectory::{Generator, Trajectory};

mod common;
use common::{random_from_state, table4_request};

fn benches(c: &mut Criterion) {
    // Planning into an existing trajectory, as a planner loop does (plan() by value
    // adds one ~4 kB move).
    let r2r = table4_request();
    let mut out = Trajectory::empty();
    c.bench_function("trajectory/plan_rest_to_rest_6", |b| {
        b.iter(|| out.plan_into(black_box(&r2r)))
    });
    let problems = random_from_state(256);
    let mut k = 0;
    c.bench_function("trajectory/plan_from_state_6", |b| {
        b.iter(|| {
            k = (k + 1) % problems.len();
            out.plan_into(black_box(&problems[k]))
        })
    });
    let tr = Trajectory::plan(&r2r).expect("Table 4 plans");
    // Sampling in place, into one kept Sample: the planner's per-cycle form, and the
    // form of Ruckig's `at_time(t, position, velocity, acceleration)`.
    let mut t = 0.0;
    let mut out = microrobot_trajectory::Sample::default();
    c.bench_function("trajectory/sample_6", |b| {
        b.iter(|| {
            t += 0.001;
            if t > 5.0 {
                t = 0.0;
            }
            tr.sample_into(black_box(t), &mut out);
            black_box(&mut out);
        })
    });
    // The same returning the 256-byte Sample by value (black_box copies it).
    t = 0.0;
    c.bench_function("trajectory/sample_by_value_6", |b| {
        b.iter(|| {
            t += 0.001;
            if t > 5.0 {
                t = 0.0;
            }
            tr.sample(black_box(t))
        })
    });
    // The planner's per-cycle call: 1 kHz steps into its current sample.
    let mut g = Generator::new(tr);
    c.bench_function("trajectory/generator_update_6", |b| {
        b.iter(|| {
            if g.time() > 5.0 {
                g.replace(tr);
            }
            black_box(g.update_into(black_box(0.001), &mut out));
            black_box(&mut out);
        })
    });
}

criterion_group!(benches_group, benches);
criterion_main!(benches_group);
