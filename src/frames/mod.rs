//! Leaf layer: frame-tagged 3-vectors, couplings and mounts (the "cheap half" of sguaba).
//!
//! A [`V3<F>`] is a plain `[f64; 3]` with a zero-size frame marker, so a stand-frame
//! vector cannot be handed to code that expects a sensor-frame one. A
//! [`Coupling<From, To>`] is a 3×3 matrix that maps `From` quantities to `To`
//! quantities; its [`Coupling::try_inverse`] maps them back, so "forward model versus
//! its inverse" is a type, not a comment.

pub mod mount;

pub use mount::{Mount, MountError};

use nalgebra::{Matrix3, Vector3};
use std::marker::PhantomData;

/// Marker: the stand's axes (the frame the motion kinematics are defined in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stand;
/// Marker: a true physical quantity (rate, angular acceleration, specific force) in the
/// sensor block's axes: what the stand's motion is in sensor axes, and what a correction
/// estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sensor;
/// Marker: what the sensor outputs (before correction), in the sensor block's axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Output;

/// A 3-vector tagged with the frame (or quantity) it lives in. Indexing gives its
/// components; [`V3::xyz`] the plain array.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(transparent)]
pub struct V3<F> {
    /// Components along the frame's x, y, z axes.
    pub xyz: [f64; 3],
    _frame: PhantomData<F>,
}

impl<F> V3<F> {
    /// Tags raw components with frame `F`.
    pub const fn new(xyz: [f64; 3]) -> Self {
        Self { xyz, _frame: PhantomData }
    }

    /// The components scaled by `k`, in the same frame.
    pub fn scaled(self, k: f64) -> Self {
        Self::new(self.xyz.map(|x| x * k))
    }
}

impl<F> From<[f64; 3]> for V3<F> {
    fn from(xyz: [f64; 3]) -> Self {
        Self::new(xyz)
    }
}

impl<F> std::ops::Index<usize> for V3<F> {
    type Output = f64;

    #[inline]
    fn index(&self, i: usize) -> &f64 {
        &self.xyz[i]
    }
}

impl<F> std::ops::IndexMut<usize> for V3<F> {
    #[inline]
    fn index_mut(&mut self, i: usize) -> &mut f64 {
        &mut self.xyz[i]
    }
}

/// A linear map from quantities of kind `From` to kind `To` (row-major: `m[(i, j)]` is the
/// weight of input component j in output component i).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coupling<From, To> {
    m: Matrix3<f64>,
    _kinds: PhantomData<(From, To)>,
}

impl<From, To> Coupling<From, To> {
    /// Wraps a matrix (row i = output axis i).
    pub fn new(m: Matrix3<f64>) -> Self {
        Self { m, _kinds: PhantomData }
    }

    /// The underlying matrix.
    pub fn matrix(&self) -> &Matrix3<f64> {
        &self.m
    }

    /// Applies the map: `to = M from`.
    #[inline]
    pub fn apply(&self, v: V3<From>) -> V3<To> {
        let r = self.m * Vector3::from(v.xyz);
        V3::new([r[0], r[1], r[2]])
    }

    /// The inverse map, or `None` when the matrix is singular.
    pub fn try_inverse(&self) -> Option<Coupling<To, From>> {
        self.m.try_inverse().map(Coupling::new)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_round_trip() {
        let c: Coupling<Sensor, Output> = Coupling::new(Matrix3::new(1.0, 0.01, 0.0, 0.0, 1.0, 0.01, 0.01, 0.0, 1.0));
        let inv = c.try_inverse().unwrap();
        let x = V3::<Sensor>::new([0.3, -1.2, 2.5]);
        let back = inv.apply(c.apply(x));
        for i in 0..3 {
            assert!((back.xyz[i] - x.xyz[i]).abs() < 1e-15);
        }
    }
}
