//! Velocity and acceleration limits on the tool's commanded position.
//!
//! A second-order tracking limiter: each cycle the desired velocity is the target's
//! own velocity plus a correction towards it of speed min(√(2 a_max |e|), |e| / dt)
//! (the first term brakes in time to stop at a still target, the second lands on
//! it exactly), capped at v_max; the velocity may change by at most a_max·dt per
//! cycle. A target moving within the limits is followed exactly (transparent).

use nalgebra::Vector3;

/// Commanded tool point and its velocity, advanced once per cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CartesianLimiter {
    /// Commanded position (m, base frame).
    pub position: Vector3<f64>,
    /// Commanded velocity (m/s).
    pub velocity: Vector3<f64>,
    max_velocity: f64,
    max_acceleration: f64,
    dt: f64,
}

impl CartesianLimiter {
    /// At rest at `position`, with limits in m/s and m/s² and the cycle `dt` (s).
    pub fn new(position: Vector3<f64>, max_velocity: f64, max_acceleration: f64, dt: f64) -> Self {
        Self {
            position,
            velocity: Vector3::zeros(),
            max_velocity,
            max_acceleration,
            dt,
        }
    }

    /// Where the command comes to rest if it brakes now at the acceleration limit.
    pub fn stopping_point(&self) -> Vector3<f64> {
        let v = self.velocity.norm();
        if v == 0.0 {
            return self.position;
        }
        self.position + self.velocity * (v / (2.0 * self.max_acceleration))
    }

    /// Stops at once at `position` (the workspace edge): velocity zero.
    pub fn stop_at(&mut self, position: Vector3<f64>) {
        self.position = position;
        self.velocity = Vector3::zeros();
    }

    /// One cycle towards `target` (which moves at `target_velocity`, m/s) with the
    /// speed limit scaled by `speed_scale` (0, 1] (slowing near singularities).
    /// Returns whether a limit was active.
    #[inline]
    pub fn step(
        &mut self,
        target: &Vector3<f64>,
        target_velocity: &Vector3<f64>,
        speed_scale: f64,
    ) -> bool {
        // Error against where the target was a cycle ago: a command that followed it
        // there moves on at the target's velocity alone and lands on it.
        let e = target - target_velocity * self.dt - self.position;
        let dist = e.norm();
        let vmax = self.max_velocity * speed_scale;
        let exact = dist / self.dt;
        let speed = exact.min((2.0 * self.max_acceleration * dist).sqrt());
        let correction = if dist > 0.0 {
            e * (speed / dist)
        } else {
            Vector3::zeros()
        };
        let mut limited = speed < exact * (1.0 - 1e-9);
        let mut desired = target_velocity + correction;
        let v = desired.norm();
        if v > vmax {
            desired *= vmax / v;
            limited = true;
        }
        let mut dv = desired - self.velocity;
        let dv_max = self.max_acceleration * self.dt;
        let n = dv.norm();
        if n > dv_max {
            dv *= dv_max / n;
            limited = true;
        }
        self.velocity += dv;
        self.position += self.velocity * self.dt;
        limited && dist > 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_targets_are_followed_exactly() {
        let dt = 1e-3;
        let mut l = CartesianLimiter::new(Vector3::zeros(), 0.05, 0.5, dt);
        for i in 1..=2000 {
            let t = i as f64 * dt;
            // 1 mm at 0.5 Hz: 3 mm/s, 10 mm/s², well within the limits.
            let w = std::f64::consts::PI;
            let target = Vector3::new(1e-3 * (w * t).sin().powi(2), 0.0, 0.0);
            let velocity = Vector3::new(1e-3 * w * (2.0 * w * t).sin(), 0.0, 0.0);
            let limited = l.step(&target, &velocity, 1.0);
            if i > 10 {
                assert!(!limited, "at {t}");
                // One cycle's ½·a·dt² behind at most (10 mm/s²: 5 nm).
                assert!((l.position - target).norm() < 1e-8, "at {t}");
            }
        }
    }

    #[test]
    fn a_step_is_reached_within_velocity_and_acceleration_limits() {
        let dt = 1e-3;
        let (vmax, amax) = (0.05, 0.5);
        let mut l = CartesianLimiter::new(Vector3::zeros(), vmax, amax, dt);
        let target = Vector3::new(0.01, -0.01, 0.005);
        let mut prev_v = Vector3::zeros();
        let mut was_limited = false;
        for _ in 0..5000 {
            was_limited |= l.step(&target, &Vector3::zeros(), 1.0);
            assert!(l.velocity.norm() <= vmax + 1e-12);
            assert!((l.velocity - prev_v).norm() <= amax * dt + 1e-12);
            prev_v = l.velocity;
        }
        assert!(was_limited);
        assert!((l.position - target).norm() < 1e-9, "{}", l.position);
        assert!(l.velocity.norm() < 1e-9);
        // Half the speed near a singularity.
        let mut slow = CartesianLimiter::new(Vector3::zeros(), vmax, amax, dt);
        for _ in 0..1000 {
            slow.step(&target, &Vector3::zeros(), 0.5);
            assert!(slow.velocity.norm() <= 0.5 * vmax + 1e-12);
        }
    }

    #[test]
    fn the_stopping_point_is_where_braking_ends() {
        let dt = 1e-3;
        let mut l = CartesianLimiter::new(Vector3::zeros(), 0.05, 0.5, dt);
        for _ in 0..300 {
            l.step(&Vector3::new(1.0, 0.0, 0.0), &Vector3::zeros(), 1.0);
        }
        let stop = l.stopping_point();
        for _ in 0..1000 {
            l.step(&stop, &Vector3::zeros(), 1.0);
        }
        assert!((l.position - stop).norm() < 1e-6 && l.velocity.norm() < 1e-9);
    }
}
