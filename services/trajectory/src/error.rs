//! Planning errors: every one names the joint (0-based index) and the offending field.

/// Why a motion could not be planned. Never a panic: bad input is one of these.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// `dof` outside 1..=MAX_JOINTS.
    #[error("dof must be in 1..=8, got {0}")]
    BadDof(usize),
    /// A NaN or infinite input value.
    #[error("joint[{joint}]: {field} is not finite ({value})")]
    NotFinite {
        /// Joint index.
        joint: usize,
        /// Field name, e.g. `limits.velocity`.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// A limit or duration that must be strictly positive.
    #[error("joint[{joint}]: {field} must be > 0, got {value}")]
    NotPositive {
        /// Joint index.
        joint: usize,
        /// Field name.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// A value outside its allowed range (e.g. a target outside the position limits).
    #[error("joint[{joint}]: {field} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        /// Joint index.
        joint: usize,
        /// Field name.
        field: &'static str,
        /// The value.
        value: f64,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
    /// The planned motion would leave the position limits (e.g. braking overruns).
    #[error("joint[{joint}]: motion reaches q = {reached}, beyond {field} = {limit}")]
    PositionOverrun {
        /// Joint index.
        joint: usize,
        /// `limits.position_min` or `limits.position_max`.
        field: &'static str,
        /// Extreme position reached.
        reached: f64,
        /// The limit.
        limit: f64,
    },
    /// A profile cannot meet the request (e.g. LSPB with non-zero boundary velocity).
    #[error("joint[{joint}]: {field}: {reason}")]
    Unsupported {
        /// Joint index.
        joint: usize,
        /// Field name.
        field: &'static str,
        /// Why.
        reason: &'static str,
    },
}
