//! Per-axis conversion between drive units and joint SI units, precomputed once.
//!
//! A CiA 402 drive speaks encoder counts on the motor side (position actual 0x6064,
//! velocity actual 0x606C, target position 0x607A) and torque in per mille of the
//! motor's rated torque (0x6076: target torque 0x6071, torque actual 0x6077). The
//! pipeline speaks joint units: rad and N·m for a revolute joint, m and N for a
//! prismatic one. [`AxisScaling`] holds the factors between the two so the cycle does a
//! multiplication per value.
//!
//! The transmission is taken as ideal (no efficiency, no backlash): joint effort times
//! joint travel per motor revolution over 2π is the motor torque.

use std::f64::consts::TAU;

/// How one motor revolution moves the joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Transmission {
    /// Revolute joint behind a gear: `gear_ratio` motor revolutions per joint
    /// revolution (positive).
    Revolute {
        /// Motor revolutions per joint revolution.
        gear_ratio: f64,
    },
    /// Prismatic joint: `lead_m_per_rev` metres of joint travel per motor revolution
    /// (screw lead over any gear in front of it; positive).
    Prismatic {
        /// Joint travel per motor revolution (m).
        lead_m_per_rev: f64,
    },
}

impl Transmission {
    /// Joint travel per motor revolution: rad for a revolute joint, m for a prismatic
    /// one.
    pub fn joint_per_motor_rev(self) -> f64 {
        match self {
            Transmission::Revolute { gear_ratio } => TAU / gear_ratio,
            Transmission::Prismatic { lead_m_per_rev } => lead_m_per_rev,
        }
    }
}

/// A scaling parameter out of range; `key` names it as in the drive file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {message}")]
pub struct ScalingError {
    /// The parameter (drive-file key name).
    pub key: &'static str,
    /// What is wrong with its value.
    pub message: String,
}

/// A target torque (0x6071) in per mille of rated motor torque, limited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TargetTorque {
    /// The value to write to 0x6071.
    pub per_mille: i16,
    /// The asked effort was beyond the limit (max torque, or the i16 range) and was
    /// clipped to it, or was not a number and was replaced by zero.
    pub saturated: bool,
}

/// A target position (0x607A) in motor encoder counts, limited to the i32 range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TargetPosition {
    /// The value to write to 0x607A.
    pub counts: i32,
    /// The asked position was outside the i32 range and was clipped to it, or was not a
    /// number and was replaced by zero.
    pub saturated: bool,
}

/// One axis's conversions, precomputed from its encoder resolution, transmission and
/// rated torque (0x6076). Joint units are rad, rad/s and N·m for a revolute joint, m,
/// m/s and N for a prismatic one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisScaling {
    transmission: Transmission,
    counts_per_rev: u32,
    rated_torque_nm: f64,
    /// Joint unit per encoder count.
    joint_per_count: f64,
    /// Encoder counts per joint unit.
    counts_per_joint: f64,
    /// Per mille of rated motor torque per joint effort unit.
    per_mille_per_effort: f64,
    /// Joint effort unit per per mille of rated motor torque.
    effort_per_per_mille: f64,
    /// The largest |target torque| sent, per mille.
    limit_per_mille: f64,
}

impl AxisScaling {
    /// The conversions for an axis with `counts_per_rev` encoder counts per motor
    /// revolution, the given transmission and `rated_torque_nm` (0x6076, motor side,
    /// N·m). The target torque is limited to `max_torque_nm` (motor side, N·m), which
    /// must be at least the rated torque and fit 0x6071's i16 range.
    pub fn new(
        counts_per_rev: u32,
        transmission: Transmission,
        rated_torque_nm: f64,
        max_torque_nm: f64,
    ) -> Result<AxisScaling, ScalingError> {
        let bad = |key: &'static str, message: String| ScalingError { key, message };
        let positive = |key: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(key, format!("must be positive, got {v}")))
            }
        };
        if counts_per_rev == 0 {
            return Err(bad("counts_per_rev", "must be positive, got 0".into()));
        }
        match transmission {
            Transmission::Revolute { gear_ratio } => positive("gear_ratio", gear_ratio)?,
            Transmission::Prismatic { lead_m_per_rev } => {
                positive("lead_m_per_rev", lead_m_per_rev)?
            }
        }
        positive("rated_torque_nm", rated_torque_nm)?;
        positive("max_torque_nm", max_torque_nm)?;
        if max_torque_nm < rated_torque_nm {
            return Err(bad(
                "max_torque_nm",
                format!(
                    "must be at least rated_torque_nm ({rated_torque_nm}), got {max_torque_nm}"
                ),
            ));
        }
        let limit_per_mille = max_torque_nm / rated_torque_nm * 1000.0;
        // Rounded, so that a ratio written to the per mille (32.767) is not refused for
        // the last bit of its product.
        if limit_per_mille.round() > f64::from(i16::MAX) {
            return Err(bad(
                "max_torque_nm",
                format!(
                    "{max_torque_nm} is {limit_per_mille:.0} per mille of rated_torque_nm \
                     ({rated_torque_nm}); 0x6071 holds at most {}",
                    i16::MAX
                ),
            ));
        }
        let limit_per_mille = limit_per_mille.min(f64::from(i16::MAX));

        let per_rev = transmission.joint_per_motor_rev();
        let cpr = f64::from(counts_per_rev);
        // Motor torque = joint effort · (joint travel per motor revolution) / 2π.
        let motor_nm_per_effort = per_rev / TAU;
        let per_mille_per_effort = motor_nm_per_effort / rated_torque_nm * 1000.0;
        Ok(AxisScaling {
            transmission,
            counts_per_rev,
            rated_torque_nm,
            joint_per_count: per_rev / cpr,
            counts_per_joint: cpr / per_rev,
            per_mille_per_effort,
            effort_per_per_mille: 1.0 / per_mille_per_effort,
            limit_per_mille,
        })
    }

    /// The transmission the axis was built with.
    pub const fn transmission(&self) -> Transmission {
        self.transmission
    }

    /// Encoder counts per motor revolution.
    pub const fn counts_per_rev(&self) -> u32 {
        self.counts_per_rev
    }

    /// Rated motor torque (0x6076), N·m.
    pub const fn rated_torque_nm(&self) -> f64 {
        self.rated_torque_nm
    }

    /// The torque limit in per mille of rated torque, for the drive's max torque
    /// (0x6072), rounded down so the drive limit is never above the configured one.
    pub fn max_torque_per_mille(&self) -> u16 {
        // At most i16::MAX by construction.
        self.limit_per_mille.floor() as u16
    }

    /// Joint position (rad or m) from a position in counts (0x6064).
    pub fn position_from_counts(&self, counts: i32) -> f64 {
        f64::from(counts) * self.joint_per_count
    }

    /// Joint velocity (rad/s or m/s) from a velocity in counts/s (0x606C).
    pub fn velocity_from_counts(&self, counts_per_s: i32) -> f64 {
        f64::from(counts_per_s) * self.joint_per_count
    }

    /// Target position (0x607A, counts) for a joint position (rad or m), rounded to the
    /// nearest count and clipped to i32 with a flag.
    pub fn position_to_counts(&self, joint: f64) -> TargetPosition {
        if !joint.is_finite() {
            return TargetPosition {
                counts: 0,
                saturated: true,
            };
        }
        let counts = (joint * self.counts_per_joint).round();
        let clipped = counts.clamp(f64::from(i32::MIN), f64::from(i32::MAX));
        TargetPosition {
            // In range after the clamp.
            counts: clipped as i32,
            saturated: clipped != counts,
        }
    }

    /// Target torque (0x6071, per mille of rated motor torque) for a joint effort (N·m
    /// or N), rounded to the nearest per mille and clipped to ± the max torque with a
    /// flag. A non-finite effort gives zero torque, flagged.
    pub fn effort_to_target_torque(&self, effort: f64) -> TargetTorque {
        if !effort.is_finite() {
            return TargetTorque {
                per_mille: 0,
                saturated: true,
            };
        }
        let wanted = effort * self.per_mille_per_effort;
        let limit = self.limit_per_mille.floor();
        TargetTorque {
            // |value| <= i16::MAX by construction.
            per_mille: wanted.round().clamp(-limit, limit) as i16,
            // Beyond the limit by more than rounding error in the factors.
            saturated: wanted.abs() > self.limit_per_mille * (1.0 + 1e-9),
        }
    }

    /// Joint effort (N·m or N) from a torque in per mille of rated motor torque (torque
    /// actual 0x6077, or a target torque 0x6071 as sent).
    pub fn effort_from_torque_actual(&self, per_mille: i16) -> f64 {
        f64::from(per_mille) * self.effort_per_per_mille
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The example drive: 2^20 counts, 100:1, 1.27 N·m rated, 3.8 N·m max.
    fn revolute() -> AxisScaling {
        AxisScaling::new(
            1 << 20,
            Transmission::Revolute { gear_ratio: 100.0 },
            1.27,
            3.8,
        )
        .expect("valid scaling")
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn gear_ratio_scales_position_and_velocity() {
        let s = revolute();
        // 100 motor revolutions are one joint revolution.
        assert!(close(s.position_from_counts(100 << 20), TAU, 1e-12));
        // One motor revolution is 2π/100 rad.
        assert!(close(s.position_from_counts(1 << 20), TAU / 100.0, 1e-15));
        // 1 motor rev/s is 2π/100 rad/s.
        assert!(close(s.velocity_from_counts(1 << 20), TAU / 100.0, 1e-15));
        let g50 = AxisScaling::new(
            1 << 20,
            Transmission::Revolute { gear_ratio: 50.0 },
            1.27,
            3.8,
        )
        .expect("valid");
        assert!(close(g50.position_from_counts(1 << 20), TAU / 50.0, 1e-15));
    }

    #[test]
    fn sign_is_kept() {
        let s = revolute();
        assert!(s.position_from_counts(-1000) < 0.0);
        assert!(s.velocity_from_counts(-1000) < 0.0);
        assert!(s.effort_to_target_torque(-10.0).per_mille < 0);
        assert!(s.effort_from_torque_actual(-100) < 0.0);
        assert!(s.position_to_counts(-0.5).counts < 0);
        assert_eq!(
            s.effort_to_target_torque(-10.0).per_mille,
            -s.effort_to_target_torque(10.0).per_mille
        );
    }

    #[test]
    fn torque_goes_through_the_gear() {
        let s = revolute();
        // 127 N·m at the joint is 1.27 N·m at the motor: rated, 1000 per mille.
        let t = s.effort_to_target_torque(127.0);
        assert_eq!(
            t,
            TargetTorque {
                per_mille: 1000,
                saturated: false
            }
        );
        assert!(close(s.effort_from_torque_actual(1000), 127.0, 1e-9));
        assert!(close(s.effort_from_torque_actual(1), 0.127, 1e-12));
    }

    #[test]
    fn round_trips() {
        let s = revolute();
        for counts in [0, 1, -1, 12345, -987_654, 100 << 20, i32::MAX, i32::MIN] {
            let q = s.position_from_counts(counts);
            assert_eq!(s.position_to_counts(q).counts, counts, "{counts}");
        }
        for q in [0.0, 0.1, -1.0, PI, -PI, 10.0] {
            let back = s.position_from_counts(s.position_to_counts(q).counts);
            // Within half a count.
            assert!(
                close(back, q, 0.5 * TAU / 100.0 / f64::from(1u32 << 20)),
                "{q}"
            );
        }
        for per_mille in [0i16, 1, -1, 500, -1000, 2992, -2992] {
            let tau = s.effort_from_torque_actual(per_mille);
            let t = s.effort_to_target_torque(tau);
            assert_eq!(
                t,
                TargetTorque {
                    per_mille,
                    saturated: false
                },
                "{per_mille}"
            );
        }
    }

    #[test]
    fn target_torque_saturates_at_max_torque_with_a_flag() {
        let s = revolute();
        // 3.8 / 1.27 = 2992.1 per mille; the limit rounds down.
        assert_eq!(s.max_torque_per_mille(), 2992);
        // Exactly the max torque (3.8 N·m at the motor) is not beyond it.
        assert_eq!(
            s.effort_to_target_torque(380.0),
            TargetTorque {
                per_mille: 2992,
                saturated: false
            }
        );
        assert_eq!(
            s.effort_to_target_torque(381.0),
            TargetTorque {
                per_mille: 2992,
                saturated: true
            }
        );
        assert_eq!(
            s.effort_to_target_torque(-1e9),
            TargetTorque {
                per_mille: -2992,
                saturated: true
            }
        );
        assert_eq!(
            s.effort_to_target_torque(f64::NAN),
            TargetTorque {
                per_mille: 0,
                saturated: true
            }
        );
        assert_eq!(
            s.effort_to_target_torque(f64::INFINITY),
            TargetTorque {
                per_mille: 0,
                saturated: true
            }
        );
    }

    #[test]
    fn target_torque_saturates_at_the_i16_range() {
        // Max torque 32.767 times rated: the limit is the whole i16 range.
        let s = AxisScaling::new(
            4096,
            Transmission::Revolute { gear_ratio: 1.0 },
            1.0,
            32.767,
        )
        .expect("valid");
        assert_eq!(s.max_torque_per_mille(), 32767);
        assert_eq!(
            s.effort_to_target_torque(1e6),
            TargetTorque {
                per_mille: i16::MAX,
                saturated: true
            }
        );
        assert_eq!(
            s.effort_to_target_torque(-1e6),
            TargetTorque {
                per_mille: -i16::MAX,
                saturated: true
            }
        );
        // Beyond it is refused up front.
        let e = AxisScaling::new(4096, Transmission::Revolute { gear_ratio: 1.0 }, 1.0, 33.0)
            .expect_err("beyond i16");
        assert_eq!(e.key, "max_torque_nm");
    }

    #[test]
    fn target_position_saturates_at_the_i32_range() {
        let s = revolute();
        let t = s.position_to_counts(1e9);
        assert_eq!(
            t,
            TargetPosition {
                counts: i32::MAX,
                saturated: true
            }
        );
        let t = s.position_to_counts(-1e9);
        assert_eq!(
            t,
            TargetPosition {
                counts: i32::MIN,
                saturated: true
            }
        );
        let t = s.position_to_counts(f64::NAN);
        assert_eq!(
            t,
            TargetPosition {
                counts: 0,
                saturated: true
            }
        );
    }

    #[test]
    fn prismatic_uses_the_lead() {
        // 5 mm per motor revolution, 10000 counts per revolution.
        let s = AxisScaling::new(
            10_000,
            Transmission::Prismatic {
                lead_m_per_rev: 0.005,
            },
            0.5,
            1.5,
        )
        .expect("valid");
        assert!(close(s.position_from_counts(10_000), 0.005, 1e-15));
        assert!(close(s.velocity_from_counts(-20_000), -0.010, 1e-15));
        assert_eq!(s.position_to_counts(0.0025).counts, 5_000);
        // F = τ·2π/lead: 0.5 N·m rated is 628.3 N.
        let rated_force = 0.5 * TAU / 0.005;
        assert!(close(s.effort_from_torque_actual(1000), rated_force, 1e-9));
        assert_eq!(s.effort_to_target_torque(rated_force).per_mille, 1000);
        assert_eq!(
            s.effort_to_target_torque(-rated_force / 2.0).per_mille,
            -500
        );
    }

    #[test]
    fn bad_parameters_are_refused_by_key() {
        let rev = |g: f64| Transmission::Revolute { gear_ratio: g };
        let key = |r: Result<AxisScaling, ScalingError>| r.map(|_| ()).map_err(|e| e.key);
        assert_eq!(
            key(AxisScaling::new(0, rev(1.0), 1.0, 1.0)),
            Err("counts_per_rev")
        );
        assert_eq!(
            key(AxisScaling::new(1, rev(-3.0), 1.0, 1.0)),
            Err("gear_ratio")
        );
        assert_eq!(
            key(AxisScaling::new(1, rev(f64::NAN), 1.0, 1.0)),
            Err("gear_ratio")
        );
        let prismatic = Transmission::Prismatic {
            lead_m_per_rev: 0.0,
        };
        assert_eq!(
            key(AxisScaling::new(1, prismatic, 1.0, 1.0)),
            Err("lead_m_per_rev")
        );
        assert_eq!(
            key(AxisScaling::new(1, rev(1.0), 0.0, 1.0)),
            Err("rated_torque_nm")
        );
        assert_eq!(
            key(AxisScaling::new(1, rev(1.0), 2.0, 1.0)),
            Err("max_torque_nm")
        );
        assert_eq!(
            AxisScaling::new(1, rev(-3.0), 1.0, 1.0).map_err(|e| e.to_string()),
            Err("gear_ratio: must be positive, got -3".to_string())
        );
        // Max equal to rated is fine.
        assert!(AxisScaling::new(1, rev(1.0), 2.0, 2.0).is_ok());
    }
}
