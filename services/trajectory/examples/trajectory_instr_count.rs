//! Fixed workloads for instruction counting under callgrind (repeatable on a loaded
//! machine, unlike timings). Each workload is one non-inlined function, so
//! `--toggle-collect` counts only it:
//!
//! ```sh
//! valgrind --tool=callgrind --toggle-collect='*run_from_state*' \
//!     target/release/examples/trajectory_instr_count from_state 256
//! ```
//!
//! Workloads: `rest_to_rest` (Table 4), `from_state` (the bench's 256 random
//! problems, cycled), `sample` (Table 4 sampled every 1 ms over 5 s), `sample_into`
//! (the same into one kept `Sample`). The second
//! argument is the number of calls; Ir / calls is the cost per call.

#[path = "../benches/common/mod.rs"]
mod common;

use std::hint::black_box;

use microrobot_trajectory::{MotionRequest, Trajectory};

#[inline(never)]
fn run_rest_to_rest(req: &MotionRequest, out: &mut Trajectory, n: usize) {
    for _ in 0..n {
        let _ = black_box(out.plan_into(black_box(req)));
    }
}

#[inline(never)]
fn run_from_state(problems: &[MotionRequest], out: &mut Trajectory, n: usize) {
    for k in 0..n {
        let _ = black_box(out.plan_into(black_box(&problems[k % problems.len()])));
    }
}

#[inline(never)]
fn run_sample(tr: &Trajectory, n: usize) {
    let mut t = 0.0;
    for _ in 0..n {
        t += 0.001;
        if t > 5.0 {
            t = 0.0;
        }
        black_box(tr.sample(black_box(t)));
    }
}

#[inline(never)]
fn run_sample_into(tr: &Trajectory, n: usize) {
    let mut t = 0.0;
    let mut out = microrobot_trajectory::Sample::default();
    for _ in 0..n {
        t += 0.001;
        if t > 5.0 {
            t = 0.0;
        }
        tr.sample_into(black_box(t), &mut out);
        black_box(&mut out);
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let which = args.next().unwrap_or_else(|| "from_state".into());
    let n: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(256);
    let r2r = common::table4_request();
    let mut out = Trajectory::empty();
    match which.as_str() {
        "rest_to_rest" => run_rest_to_rest(&r2r, &mut out, n),
        "from_state" => {
            let problems = common::random_from_state(256);
            run_from_state(&problems, &mut out, n);
        }
        "sample" => match Trajectory::plan(&r2r) {
            Ok(tr) => run_sample(&tr, n),
            Err(e) => eprintln!("Table 4 does not plan: {e}"),
        },
        "sample_into" => match Trajectory::plan(&r2r) {
            Ok(tr) => run_sample_into(&tr, n),
            Err(e) => eprintln!("Table 4 does not plan: {e}"),
        },
        other => {
            eprintln!("unknown workload {other}: rest_to_rest | from_state | sample | sample_into")
        }
    }
}
