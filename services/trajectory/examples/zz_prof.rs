#[path = "../benches/common/mod.rs"]
mod common;
use microrobot_trajectory::Trajectory;
use std::hint::black_box;
fn main() {
    let mode = std::env::args().nth(1).unwrap_or_default();
    let r2r = common::table4_request();
    let problems = common::random_from_state(256);
    let mut out = Trajectory::empty();
    for k in 0..2_000_000usize {
        if mode == "r2r" {
            let _ = black_box(out.plan_into(black_box(&r2r)));
        } else {
            let _ = black_box(out.plan_into(black_box(&problems[k % 256])));
        }
    }
}
