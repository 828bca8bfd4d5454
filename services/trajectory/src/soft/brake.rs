//! Brake pre-phase: bring a state whose velocity limit is bound to be crossed
//! (|v + a|a|/(2 jmax)| > vmax) or whose |a| exceeds amax back inside the limits.
//!
//! Ruckig's velocity brake (`BrakeProfile::velocity_brake`), mirrored for the
//! negative side: jerk −jmax until the velocity is back at vmax, holding −amax if it
//! is reached first, and ending early if the stop velocity v − a²/(2 jmax) reaches
//! −vmax (braking on would overshoot the limit on the other side). While a > 0 the
//! velocity still grows by a²/(2 jmax) — unavoidable with bounded jerk — and from
//! then on |v| only decreases; the time spent over vmax is the least the jerk limit
//! allows. (Braking only until the stop velocity equals vmax instead would glide
//! down onto vmax, faster overall but over the limit for longer — up to a third of a
//! second in random problems.)

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
    let mut k = Kin { p: 0.0, v, a };
    if a < -am {
        // Decelerating harder than amax (a measured state): ease off to −amax first.
        let t = (-am - a) / jm;
        ph.push(t, sg * jm);
        k = k.advance(t, jm);
        if k.v <= vm {
            return ph;
        }
    }
    // −J until v = vmax (the later root of v + a t − J t²/2 = vmax; a < 0 by then),
    // or earlier if the stop velocity v − a²/(2J) reaches −vmax first: braking on
    // would then force |v| over vmax on the other side.
    let t_v = (k.a + (k.a * k.a + 2.0 * jm * (k.v - vm)).max(0.0).sqrt()) / jm;
    let t_s = (k.a + (0.5 * k.a * k.a + jm * (k.v + vm)).max(0.0).sqrt()) / jm;
    let t = t_v.min(t_s);
    let t_acc = ((k.a + am) / jm).max(0.0);
    if t <= t_acc {
        ph.push(t, -sg * jm);
    } else {
        // −amax reached first: hold it until v = vmax, or the stop velocity −vmax.
        ph.push(t_acc, -sg * jm);
        let at_amax = k.advance(t_acc, -jm);
        let hold_v = (at_amax.v - vm) / am;
        let hold_s = (at_amax.v - am * am / (2.0 * jm) + vm) / am;
        ph.push(hold_v.min(hold_s).max(0.0), 0.0);
    }
    ph
}
