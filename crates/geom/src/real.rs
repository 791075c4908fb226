//! The float trait every differentiable kernel is generic over, so that tests can run the same
//! code in f64 against finite differences while the hot paths run in f32.

use nalgebra::RealField;

/// `f32` or `f64`.
pub trait Real: RealField + Copy + Send + Sync + std::fmt::Debug + 'static {
    /// Converts from `f64` (rounding for `f32`).
    fn of(x: f64) -> Self;
    /// Converts to `f64` (exact).
    fn to_f64(self) -> f64;
    /// Machine epsilon of the type.
    fn eps() -> Self;
}

impl Real for f32 {
    #[inline]
    fn of(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn eps() -> Self {
        f32::EPSILON
    }
}

impl Real for f64 {
    #[inline]
    fn of(x: f64) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn eps() -> Self {
        f64::EPSILON
    }
}
