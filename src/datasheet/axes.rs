//! The sensing axes of a triad out of its scale-coupling matrix (gyro C_ω, accelerometer K):
//! scale factors, axis-to-axis non-orthogonality and the rotation of the axes to the
//! reference frame.
//!
//! Row i of M (C or K) is the sensing axis of output i, in the reference frame, times its
//! scale factor: u_i = s_i n_i · x. So
//!
//! ```text
//!   M = diag(s) N,   s_i = |row i of M|,   N = rows n_i = M_i / s_i  (unit vectors)
//!   N = P R          (polar decomposition: P symmetric positive definite, R a rotation)
//! ```
//!
//! * **Non-orthogonality** of axes i and j is δ_ij = asin(n_i · n_j): how far the angle
//!   between the two sensing axes is from 90° (positive: closer than 90°). It is a property
//!   of the axes alone — every decomposition of N into "shape × rotation" gives the same
//!   δ — and is the datasheet's *axis-to-axis misalignment*.
//! * **Rotation to the reference frame** is R, the rotation closest to N (R = U Vᵀ from the
//!   SVD N = U Σ Vᵀ minimises ‖N − R‖_F: the orthogonal Procrustes solution, Higham 1986).
//!   It is reported as its rotation vector θ (R = exp([θ]×), components about x, y, z): the
//!   datasheet's *axis-to-frame alignment*.
//!
//! Why polar and not QR (N = T R with T lower-triangular, the other common choice, e.g.
//! Tedaldi et al. 2014): QR declares the x axis exact and y exact within the x–y plane, so
//! its rotation changes with the order of the axes and charges x with all of the
//! non-orthogonality. The polar factor treats the three axes alike: it is the rigid rotation
//! that best fits all three sensing axes at once, which is what "the rotation of the block's
//! axes to the mounting frame" means. When the truth is built as N = G^½ R (G the Gram
//! matrix of the axes, G_ii = 1, G_ij = sin δ_ij, and G^½ its symmetric square root, whose
//! rows are unit vectors), the decomposition gives back δ and R exactly.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// The sensing axes of a triad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axes {
    /// Scale factor of each output, |row i of M|.
    pub scale: [f64; 3],
    /// Non-orthogonality δ_xy, δ_yz, δ_zx, rad (asin of the axes' dot products).
    pub non_orthogonality_rad: [f64; 3],
    /// Rotation vector of the rotation to the reference frame (the polar factor R), rad.
    pub rotation_rad: [f64; 3],
}

/// The axis pairs of [`Axes::non_orthogonality_rad`], in order.
pub const PAIRS: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

/// Decomposes a scale-coupling matrix (row-major, forward: output = M × input). None when a
/// row is zero or the axes are degenerate.
pub fn decompose(m: &[[f64; 3]; 3]) -> Option<Axes> {
    let mut scale = [0.0; 3];
    let mut n = Matrix3::zeros();
    for i in 0..3 {
        let row = Vector3::from(m[i]);
        let s = row.norm();
        if !(s.is_finite() && s > 0.0) {
            return None;
        }
        scale[i] = s;
        n.set_row(i, &(row / s).transpose());
    }
    let mut non_orthogonality_rad = [0.0; 3];
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        non_orthogonality_rad[k] = n.row(i).dot(&n.row(j)).clamp(-1.0, 1.0).asin();
    }
    let svd = n.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        // A left-handed triad: the nearest proper rotation flips the weakest direction.
        let k = svd.singular_values.imin();
        let mut u2 = u;
        u2.set_column(k, &(-u.column(k)));
        r = u2 * v_t;
    }
    let rot = Rotation3::from_matrix_unchecked(r).scaled_axis();
    if !rot.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some(Axes { scale, non_orthogonality_rad, rotation_rad: [rot.x, rot.y, rot.z] })
}

/// The matrix of a triad with scale factors `scale`, non-orthogonality `delta_rad` (xy, yz,
/// zx) and rotation vector `rotation_rad`: diag(s) G^½ R, the inverse of [`decompose`] (for
/// simulating units with known axes).
pub fn compose(scale: [f64; 3], delta_rad: [f64; 3], rotation_rad: [f64; 3]) -> Option<[[f64; 3]; 3]> {
    let mut g = Matrix3::identity();
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        g[(i, j)] = delta_rad[k].sin();
        g[(j, i)] = delta_rad[k].sin();
    }
    let eig = g.symmetric_eigen();
    if eig.eigenvalues.iter().any(|&l| l <= 0.0) {
        return None;
    }
    let sqrt =
        eig.eigenvectors * Matrix3::from_diagonal(&eig.eigenvalues.map(f64::sqrt)) * eig.eigenvectors.transpose();
    let r = Rotation3::from_scaled_axis(Vector3::from(rotation_rad));
    let m = Matrix3::from_diagonal(&Vector3::from(scale)) * sqrt * r.matrix();
    Some([0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise-free: known non-orthogonality and rotation come back to 1e-6 rad (in fact to
    /// rounding), whatever the scale factors.
    #[test]
    fn known_axes_come_back() {
        let delta = [0.8e-3, -1.5e-3, 0.4e-3];
        let rot = [2.0e-3, -0.7e-3, 1.1e-3];
        let scale = [1.002, 0.9985, 1.0007];
        let m = compose(scale, delta, rot).unwrap();
        let a = decompose(&m).unwrap();
        for k in 0..3 {
            assert!((a.non_orthogonality_rad[k] - delta[k]).abs() < 1e-12, "{a:?}");
            assert!((a.rotation_rad[k] - rot[k]).abs() < 1e-12, "{a:?}");
            assert!((a.scale[k] - scale[k]).abs() < 1e-12, "{a:?}");
        }
    }
}
