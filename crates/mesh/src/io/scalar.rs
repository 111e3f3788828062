//! Binary scalar types of mesh, point-cloud and image files (legacy VTK, VTK XML, PLY, NIfTI and
//! NRRD labelmaps): their size and decoding.
//! Each format names the types its own way and parses those names itself.

/// A binary scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    /// Unsigned 8-bit integer.
    U8,
    /// Signed 8-bit integer.
    I8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 16-bit integer.
    I16,
    /// Unsigned 32-bit integer.
    U32,
    /// Signed 32-bit integer.
    I32,
    /// Unsigned 64-bit integer.
    U64,
    /// Signed 64-bit integer.
    I64,
    /// 32-bit float.
    F32,
    /// 64-bit float.
    F64,
}

impl Scalar {
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Scalar::U8 | Scalar::I8 => 1,
            Scalar::U16 | Scalar::I16 => 2,
            Scalar::U32 | Scalar::I32 | Scalar::F32 => 4,
            Scalar::U64 | Scalar::I64 | Scalar::F64 => 8,
        }
    }

    /// Whether the type is an integer type.
    pub fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value from exactly `self.size()` bytes in the given byte order.
    pub fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        let mut w = [0u8; 8];
        w[..b.len()].copy_from_slice(b);
        if big_endian {
            w[..b.len()].reverse();
        }
        let (b2, b4) = ([w[0], w[1]], [w[0], w[1], w[2], w[3]]);
        match self {
            Scalar::U8 => f64::from(w[0]),
            Scalar::I8 => f64::from(w[0] as i8),
            Scalar::U16 => f64::from(u16::from_le_bytes(b2)),
            Scalar::I16 => f64::from(i16::from_le_bytes(b2)),
            Scalar::U32 => f64::from(u32::from_le_bytes(b4)),
            Scalar::I32 => f64::from(i32::from_le_bytes(b4)),
            Scalar::U64 => u64::from_le_bytes(w) as f64,
            Scalar::I64 => i64::from_le_bytes(w) as f64,
            Scalar::F32 => f64::from(f32::from_le_bytes(b4)),
            Scalar::F64 => f64::from_le_bytes(w),
        }
    }
}
