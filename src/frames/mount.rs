//! Mounts: how the sensor block sits on the stand.
//!
//! Convention (session format): `mount = ["+y", "+z", "+x"]` means the sensor's x axis lies
//! along the stand's +y, its y along +z, its z along +x. The mount matrix M has the named
//! stand unit vectors as rows, so `w_sensor = M w_stand`.

use super::{Sensor, Stand, V3};
use nalgebra::Matrix3;

/// A proper rotation from stand axes to sensor axes built from signed axis names.
#[derive(Debug, Clone, PartialEq)]
pub struct Mount {
    names: [String; 3],
    m: Matrix3<f64>,
    /// Per sensor axis: the stand axis it lies along and the sign (M's only nonzero entry
    /// in that row), so that a vector is mapped by picking and signing its components.
    perm: [(usize, f64); 3],
}

/// Why a mount is rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MountError {
    /// A name is not one of `+x -x +y -y +z -z`.
    #[error("mount axis '{0}' is not one of +x, -x, +y, -y, +z, -z")]
    BadAxis(String),
    /// Not exactly three names.
    #[error("a mount names exactly 3 axes, found {0}")]
    WrongLength(usize),
    /// Two sensor axes along the same stand axis, or a mirror (determinant −1).
    #[error(
        "mount {0:?} is not a rotation ({1}); each stand axis must appear once and the result must be right-handed"
    )]
    NotRotation(Vec<String>, &'static str),
}

fn axis(name: &str) -> Result<[f64; 3], MountError> {
    let (sign, letter) = match name.trim().as_bytes() {
        [b'+', l] => (1.0, *l),
        [b'-', l] => (-1.0, *l),
        [l] => (1.0, *l),
        _ => return Err(MountError::BadAxis(name.to_string())),
    };
    let mut v = [0.0; 3];
    match letter.to_ascii_lowercase() {
        b'x' => v[0] = sign,
        b'y' => v[1] = sign,
        b'z' => v[2] = sign,
        _ => return Err(MountError::BadAxis(name.to_string())),
    }
    Ok(v)
}

impl Mount {
    /// The nominal mount `["+x", "+y", "+z"]`.
    pub fn identity() -> Self {
        Self::from_matrix(["+x".into(), "+y".into(), "+z".into()], Matrix3::identity())
    }

    /// Parses signed axis names (rows of M); rejects anything that is not a proper rotation.
    pub fn parse<S: AsRef<str>>(names: &[S]) -> Result<Self, MountError> {
        if names.len() != 3 {
            return Err(MountError::WrongLength(names.len()));
        }
        let mut rows = [[0.0; 3]; 3];
        for (i, n) in names.iter().enumerate() {
            rows[i] = axis(n.as_ref())?;
        }
        let m = Matrix3::from_fn(|i, j| rows[i][j]);
        let owned: Vec<String> = names.iter().map(|s| s.as_ref().trim().to_string()).collect();
        let gram = m * m.transpose();
        if (gram - Matrix3::identity()).abs().max() > 1e-12 {
            return Err(MountError::NotRotation(owned, "two sensor axes share a stand axis"));
        }
        if m.determinant() < 0.0 {
            return Err(MountError::NotRotation(owned, "it is a mirror image, determinant -1"));
        }
        Ok(Self::from_matrix([owned[0].clone(), owned[1].clone(), owned[2].clone()], m))
    }

    /// The mount of a signed permutation matrix `m` (rows: unit stand axes).
    fn from_matrix(names: [String; 3], m: Matrix3<f64>) -> Self {
        let perm = std::array::from_fn(|i| {
            let j = (0..3).find(|&j| m[(i, j)] != 0.0).unwrap_or(i);
            (j, m[(i, j)])
        });
        Self { names, m, perm }
    }

    /// The axis names as written (e.g. `["+y", "+z", "+x"]`).
    pub fn names(&self) -> &[String; 3] {
        &self.names
    }

    /// The matrix M (rows = stand unit vectors of the sensor axes).
    pub fn matrix(&self) -> &Matrix3<f64> {
        &self.m
    }

    /// `v_sensor = M v_stand`.
    #[inline]
    pub fn to_sensor(&self, v: V3<Stand>) -> V3<Sensor> {
        // M is a signed permutation: each sensor component is one stand component, signed
        // (exactly M v for finite v, without the products by zero).
        let [(i0, s0), (i1, s1), (i2, s2)] = self.perm;
        V3::new([s0 * v.xyz[i0], s1 * v.xyz[i1], s2 * v.xyz[i2]])
    }

    /// `v_stand = Mᵀ v_sensor`.
    #[inline]
    pub fn to_stand(&self, v: V3<Sensor>) -> V3<Stand> {
        let mut r = [0.0; 3];
        for (k, &(i, s)) in self.perm.iter().enumerate() {
            r[i] = s * v.xyz[k];
        }
        V3::new(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyclic_mount_maps_axes() {
        let m = Mount::parse(&["+y", "+z", "+x"]).unwrap();
        let s = m.to_sensor(V3::new([1.0, 2.0, 3.0]));
        assert!(s.xyz.iter().zip([2.0, 3.0, 1.0]).all(|(a, b)| (a - b).abs() < 1e-15));
        let back = m.to_stand(s);
        assert!(back.xyz.iter().zip([1.0, 2.0, 3.0]).all(|(a, b)| (a - b).abs() < 1e-15));
    }

    #[test]
    fn every_mount_maps_as_its_matrix() {
        let names = ["+x", "-x", "+y", "-y", "+z", "-z"];
        let v = [0.3, -1.7, 2.9];
        let mut proper = 0;
        for a in names {
            for b in names {
                for c in names {
                    let Ok(m) = Mount::parse(&[a, b, c]) else { continue };
                    proper += 1;
                    let want = m.matrix() * nalgebra::Vector3::from(v);
                    assert_eq!(
                        m.to_sensor(V3::new(v)).xyz.map(f64::to_bits),
                        [want[0], want[1], want[2]].map(f64::to_bits)
                    );
                    let back = m.matrix().transpose() * nalgebra::Vector3::from(v);
                    assert_eq!(
                        m.to_stand(V3::new(v)).xyz.map(f64::to_bits),
                        [back[0], back[1], back[2]].map(f64::to_bits)
                    );
                }
            }
        }
        assert_eq!(proper, 24, "the proper rotations among signed axis permutations");
    }

    #[test]
    fn rejects_mirror_and_repeats() {
        assert!(matches!(Mount::parse(&["+y", "+x", "+z"]), Err(MountError::NotRotation(..))));
        assert!(matches!(Mount::parse(&["+x", "+x", "+z"]), Err(MountError::NotRotation(..))));
        assert!(matches!(Mount::parse(&["+x", "+q", "+z"]), Err(MountError::BadAxis(_))));
        assert!(matches!(Mount::parse(&["+x"]), Err(MountError::WrongLength(1))));
        assert!(Mount::parse(&["-x", "-y", "+z"]).is_ok());
    }
}
