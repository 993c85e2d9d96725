//! The crate's one error type ([`StatsError`]) and its result alias.

/// Errors of the numerics: invalid inputs, shapes that do not match, infeasible designs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StatsError {
    /// A triangular prior whose bounds are out of order.
    #[error("invalid triangular prior (min {min}, mode {mode}, max {max}): {reason}")]
    InvalidTriangular {
        /// Lower bound.
        min: f64,
        /// Mode.
        mode: f64,
        /// Upper bound.
        max: f64,
        /// What is out of order.
        reason: &'static str,
    },
    /// Inputs whose lengths or shapes do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// An argument outside its valid range.
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// Design rows that still violate constraints after repair.
    #[error("constraint repair failed: design rows {rows:?} still violate the constraints")]
    InfeasibleDesign {
        /// The rows (design points) still infeasible.
        rows: Vec<usize>,
    },
    /// Too few valid values for a statistic.
    #[error("not enough data: {0}")]
    NotEnoughData(String),
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, StatsError>;
