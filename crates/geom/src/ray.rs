//! Half-lines `origin + t · dir`, `t ≥ 0`.

use crate::Real;
use nalgebra::Vector3;

/// A ray. The frame is the caller's (name the variable `ray_depth`, `ray_thermal`, …).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray<T: Real> {
    /// Start point, metres.
    pub origin: Vector3<T>,
    /// Direction, unit length (constructors normalise).
    pub dir: Vector3<T>,
}

impl<T: Real> Ray<T> {
    /// A ray from `origin` along `dir` (normalised here; `dir` must be non-zero).
    pub fn new(origin: Vector3<T>, dir: Vector3<T>) -> Self {
        Self {
            origin,
            dir: dir.normalize(),
        }
    }
    /// The point at parameter `t` (metres along the ray).
    pub fn at(&self, t: T) -> Vector3<T> {
        self.origin + self.dir * t
    }
}
