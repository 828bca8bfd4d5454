//! Brake pre-phase: bring a state whose velocity limit is bound to be crossed
//! (|v + a|a|/(2 jmax)| > vmax) or whose |a| exceeds amax back inside the limits.
//!
//! Jerk −jmax (mirrored for the negative side) until the stop-velocity equals vmax,
//! holding −amax if it is reached first. While a > 0 the velocity still grows by
//! a²/(2 jmax) — unavoidable with bounded jerk — and from then on |v| only decreases.

use super::{Kin, Limits1, Phases, stop_velocity};

/// Brake phases (in the original frame) for state `k`; empty when not needed.
pub fn brake(k: Kin, lim: &Limits1) -> Phases {
    let s = stop_velocity(k.v, k.a, lim.j);
    if s > lim.v {
        down(k.v, k.a, lim, 1.0)
    } else if s < -lim.v {
        down(-k.v, -k.a, lim, -1.0)
    } else if k.a > lim.a {
        let mut ph = Phases::default();
        ph.push((k.a - lim.a) / lim.j, -lim.j);
        ph
    } else if k.a < -lim.a {
        let mut ph = Phases::default();
        ph.push((-lim.a - k.a) / lim.j, lim.j);
        ph
    } else {
        Phases::default()
    }
}

/// Positive-frame velocity brake for stop-velocity above vmax; jerks scaled by `sg`.
fn down(v: f64, a: f64, lim: &Limits1, sg: f64) -> Phases {
    let (vm, am, jm) = (lim.v, lim.a, lim.j);
    let mut ph = Phases::default();
    // −J until v − a²/(2J) = vmax (with a < 0 by then).
    let t = (a + (0.5 * a * a + jm * (v - vm)).max(0.0).sqrt()) / jm;
    let t_acc = ((a + am) / jm).max(0.0);
    if t <= t_acc {
        ph.push(t, -sg * jm);
    } else {
        ph.push(t_acc, -sg * jm);
        let k = Kin { p: 0.0, v, a }.advance(t_acc, -jm);
        let s = k.v - am * am / (2.0 * jm);
        ph.push(((s - vm) / am).max(0.0), 0.0);
    }
    ph
}
