//! The fixed-size little-endian numbers the log formats share (ROS messages, ULog fields).

/// A fixed-size number type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Num {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Num {
    /// Size in bytes.
    pub(crate) fn size(self) -> usize {
        match self {
            Num::I8 | Num::U8 => 1,
            Num::I16 | Num::U16 => 2,
            Num::I32 | Num::U32 | Num::F32 => 4,
            Num::I64 | Num::U64 | Num::F64 => 8,
        }
    }

    /// The value of the first `size()` bytes of `a`, little-endian.
    pub(crate) fn value_le(self, a: [u8; 8]) -> f64 {
        let w4 = [a[0], a[1], a[2], a[3]];
        match self {
            Num::I8 => f64::from(a[0] as i8),
            Num::U8 => f64::from(a[0]),
            Num::I16 => f64::from(i16::from_le_bytes([a[0], a[1]])),
            Num::U16 => f64::from(u16::from_le_bytes([a[0], a[1]])),
            Num::I32 => f64::from(i32::from_le_bytes(w4)),
            Num::U32 => f64::from(u32::from_le_bytes(w4)),
            Num::I64 => i64::from_le_bytes(a) as f64,
            Num::U64 => u64::from_le_bytes(a) as f64,
            Num::F32 => f64::from(f32::from_le_bytes(w4)),
            Num::F64 => f64::from_le_bytes(a),
        }
    }

    /// The value at byte `at` of `b` (None past its end).
    pub(crate) fn read_le(self, b: &[u8], at: usize) -> Option<f64> {
        let s = b.get(at..at.checked_add(self.size())?)?;
        let mut a = [0u8; 8];
        a[..s.len()].copy_from_slice(s);
        Some(self.value_le(a))
    }
}
