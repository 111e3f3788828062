//! Minimal NumPy `.npy` reader and writer.
//!
//! Writes format version 1.0 with little-endian `<f4` (f32), `<f8` (f64) or `|u1` (u8) data in C order,
//! readable by `numpy.load`. Reads versions 1.0–3.0 with float (`f4`, `f8`), integer (`i1`–`i8`,
//! `u1`–`u8`, read as f64) or bool (`b1`) data in either byte order and in C or Fortran order
//! (as `np.save` writes a transposed array), given back in C order; anything else, and any
//! truncation, is a clear error naming the file.

use std::io::Write;
use std::path::Path;

use crate::io::{write_atomic, Scalar};
use crate::MeshError;

/// A result whose error names the `.npy` file.
type Result<T> = std::result::Result<T, MeshError>;

/// The error of a malformed or truncated `.npy` file at `path`.
fn invalid(path: &Path, message: impl std::fmt::Display) -> MeshError {
    MeshError::Parse { path: path.display().to_string(), message: format!("invalid .npy file: {message}") }
}

/// The error of `path` that could not be read.
fn unread(path: &Path, error: std::io::Error) -> MeshError {
    MeshError::Io { path: path.display().to_string(), error }
}

const MAGIC: &[u8] = b"\x93NUMPY";

/// The element data of an `.npy` array.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// `f4` values.
    F32(Vec<f32>),
    /// `f8` values, or integers wider than a byte or signed.
    F64(Vec<f64>),
    /// `u1` values (or `b1`, stored as 0/1).
    U8(Vec<u8>),
}

/// An array read from an `.npy` file.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The shape (C order).
    pub shape: Vec<usize>,
    /// The values.
    pub data: NpyData,
}

impl NpyArray {
    /// The values as f32 (f64 values are rounded, u8 values converted).
    pub fn into_f32(self) -> Vec<f32> {
        match self.data {
            NpyData::F32(v) => v,
            NpyData::F64(v) => v.into_iter().map(|x| x as f32).collect(),
            NpyData::U8(v) => v.into_iter().map(f32::from).collect(),
        }
    }

    /// The values as f64 (f32 and u8 values converted exactly).
    pub fn into_f64(self) -> Vec<f64> {
        match self.data {
            NpyData::F32(v) => v.into_iter().map(f64::from).collect(),
            NpyData::F64(v) => v,
            NpyData::U8(v) => v.into_iter().map(f64::from).collect(),
        }
    }

    /// The rows of an array of shape `[N, C]` as numbers, refusing another shape and a uint8 or
    /// boolean array (a mask, not coordinates); `what` names a row in the error (`x, y, z`).
    pub fn into_rows<const C: usize>(self, path: &Path, what: &str) -> Result<Vec<[f64; C]>> {
        if self.shape.len() != 2 || self.shape[1] != C {
            let message = format!("expected an array of shape [N, {C}] ({what} per row), found {:?}", self.shape);
            return Err(invalid(path, message));
        }
        if matches!(self.data, NpyData::U8(_)) {
            return Err(invalid(path, "expected float32 or float64 values, found uint8 or bool (a mask?)"));
        }
        Ok(self.into_f64().chunks_exact(C).map(|r| std::array::from_fn(|i| r[i])).collect())
    }

    /// The values as u8 (float values must be exactly 0 or 1, as for a mask).
    pub fn into_mask(self, path: &Path) -> Result<Vec<u8>> {
        let bad = |x: f64| invalid(path, format!("mask values must be 0 or 1, found {x}"));
        match self.data {
            NpyData::U8(v) => match v.iter().find(|&&x| x > 1) {
                Some(&x) => Err(bad(f64::from(x))),
                None => Ok(v),
            },
            NpyData::F32(v) => v.into_iter().map(|x| to_mask(f64::from(x)).ok_or_else(|| bad(f64::from(x)))).collect(),
            NpyData::F64(v) => v.into_iter().map(|x| to_mask(x).ok_or_else(|| bad(x))).collect(),
        }
    }
}

fn to_mask(x: f64) -> Option<u8> {
    if x == 0.0 {
        Some(0)
    } else if x == 1.0 {
        Some(1)
    } else {
        None
    }
}

/// Builds a v1.0 header for `descr` and `shape`, padded so that the data starts on a 64-byte
/// boundary.
fn header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let shape_str = match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!("({})", shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_str}, }}");
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    dict.push_str(&" ".repeat(pad));
    dict.push('\n');
    let mut out = Vec::with_capacity(MAGIC.len() + 4 + dict.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

fn check_len(shape: &[usize], len: usize) -> Result<()> {
    let expected: usize = shape.iter().product();
    if expected != len {
        return Err(MeshError::Invalid(format!("an .npy array of shape {shape:?} needs {expected} values, got {len}")));
    }
    Ok(())
}

/// Writes f32 values of the given shape to `path` atomically (`<f4`, C order).
pub fn write_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    write_values(path, "<f4", shape, data, |x| x.to_le_bytes())
}

/// Writes f64 values of the given shape to `path` atomically (`<f8`, C order).
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<()> {
    write_values(path, "<f8", shape, data, |x| x.to_le_bytes())
}

/// Writes `data` of the given shape to `path` atomically, as `descr` says (C order), each value's
/// bytes given by `bytes`, in chunks of 64 KiB.
fn write_values<T: Copy, const N: usize>(
    path: &Path,
    descr: &str,
    shape: &[usize],
    data: &[T],
    bytes: impl Fn(T) -> [u8; N],
) -> Result<()> {
    check_len(shape, data.len())?;
    let head = header(descr, shape);
    write_atomic(path, |w| {
        w.write_all(&head)?;
        for chunk in data.chunks(65536 / N) {
            let chunk: Vec<u8> = chunk.iter().flat_map(|&x| bytes(x)).collect();
            w.write_all(&chunk)?;
        }
        Ok(())
    })?;
    Ok(())
}

/// Writes u8 values of the given shape to `path` atomically (`|u1`, C order).
pub fn write_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<()> {
    write_values(path, "|u1", shape, data, |x| [x])
}

/// Reads an `.npy` file.
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    read_npy_bytes(path).map(|(array, _)| array)
}

/// Reads an `.npy` file, with its bytes as stored (to check them against a digest).
pub fn read_npy_bytes(path: &Path) -> Result<(NpyArray, Vec<u8>)> {
    let bytes = std::fs::read(path).map_err(|e| unread(path, e))?;
    let array = parse(&bytes).map_err(|message| invalid(path, message))?;
    Ok((array, bytes))
}

/// Reads the shape of an `.npy` file from its header, without its data; a file whose length is
/// not that of the data its header announces (truncated) is an error.
pub fn read_shape(path: &Path) -> Result<Vec<usize>> {
    use std::io::Read;
    let err = |message: String| invalid(path, message);
    let mut file = std::fs::File::open(path).map_err(|e| unread(path, e))?;
    let mut head = Vec::new();
    Read::take(&mut file, 65536 + 12).read_to_end(&mut head).map_err(|e| unread(path, e))?;
    let length = file.metadata().map_err(|e| unread(path, e))?.len() as usize;
    let (header, data) = split_header(&head).map_err(err)?;
    let (descr, _, shape) = parse_header(header).map_err(err)?;
    check_data_length(&descr, &shape, length - (head.len() - data.len())).map_err(err)?;
    Ok(shape)
}

/// Refuses `data` bytes that are not those of an array of `shape` and `descr`.
fn check_data_length(descr: &str, shape: &[usize], data: usize) -> std::result::Result<(), String> {
    let (scalar, _) = element(descr)?;
    let needed = shape
        .iter()
        .try_fold(scalar.size(), |n, &d| n.checked_mul(d))
        .ok_or_else(|| format!("shape {shape:?} of {descr} holds more bytes than any file can: a damaged header?"))?;
    if data < needed {
        return Err(format!("truncated: shape {shape:?} of {descr} needs {needed} data bytes, the file has {data}"));
    }
    if data > needed {
        return Err(format!("{} trailing bytes after the data of shape {shape:?} ({descr})", data - needed));
    }
    Ok(())
}

/// Splits the file into the header dictionary text and the data bytes.
fn split_header(bytes: &[u8]) -> std::result::Result<(&str, &[u8]), String> {
    if bytes.starts_with(super::LFS_POINTER) {
        return Err(super::LFS_MESSAGE.into());
    }
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("missing the \\x93NUMPY magic string (not an .npy file, or empty)".into());
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (header_len, start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated header".into());
            }
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        _ => return Err(format!("unsupported format version {major}.{minor}")),
    };
    if bytes.len() < start + header_len {
        return Err(format!("truncated header: needs {} bytes, the file has {}", start + header_len, bytes.len()));
    }
    let header =
        std::str::from_utf8(&bytes[start..start + header_len]).map_err(|_| "header is not text".to_string())?;
    Ok((header, &bytes[start + header_len..]))
}

/// Parses the header dictionary: (descr, fortran_order, shape).
fn parse_header(header: &str) -> std::result::Result<(String, bool, Vec<usize>), String> {
    let value_of = |key: &str| -> std::result::Result<&str, String> {
        let pat = format!("'{key}':");
        let at = header.find(&pat).ok_or_else(|| format!("header has no '{key}' entry: {header:?}"))?;
        Ok(header[at + pat.len()..].trim_start())
    };
    let descr_rest = value_of("descr")?;
    let descr = descr_rest
        .strip_prefix('\'')
        .and_then(|s| s.split('\'').next())
        .ok_or_else(|| format!("cannot read 'descr' in header {header:?}"))?
        .to_string();
    let fortran_rest = value_of("fortran_order")?;
    let fortran = if fortran_rest.starts_with("True") {
        true
    } else if fortran_rest.starts_with("False") {
        false
    } else {
        return Err(format!("cannot read 'fortran_order' in header {header:?}"));
    };
    let shape_rest = value_of("shape")?;
    let inner = shape_rest
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| format!("cannot read 'shape' in header {header:?}"))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| format!("bad dimension {s:?} in shape of header {header:?}")))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    Ok((descr, fortran, shape))
}

/// The scalar type and byte order (big-endian or not) of a `descr` such as `<f8`, `>i4`, `|u1`
/// or `|b1` (a bool is read as a u1).
fn element(descr: &str) -> std::result::Result<(Scalar, bool), String> {
    let unsupported =
        || format!("unsupported dtype {descr:?} (expected floats f4/f8, integers i1–i8/u1–u8 or bool b1)");
    let (order, ty) = (descr.get(..1).unwrap_or_default(), descr.get(1..).unwrap_or_default());
    let scalar = match ty {
        "f4" => Scalar::F32,
        "f8" => Scalar::F64,
        "i1" => Scalar::I8,
        "i2" => Scalar::I16,
        "i4" => Scalar::I32,
        "i8" => Scalar::I64,
        "u1" | "b1" => Scalar::U8,
        "u2" => Scalar::U16,
        "u4" => Scalar::U32,
        "u8" => Scalar::U64,
        _ => return Err(unsupported()),
    };
    match order {
        ">" => Ok((scalar, true)),
        "<" | "|" | "=" => Ok((scalar, false)),
        _ => Err(unsupported()),
    }
}

impl NpyData {
    /// The values taken in `order` (the position of each one in `self`).
    fn reordered(self, order: &[usize]) -> NpyData {
        fn pick<T: Copy>(v: &[T], order: &[usize]) -> Vec<T> {
            order.iter().map(|&k| v[k]).collect()
        }
        match self {
            NpyData::F32(v) => NpyData::F32(pick(&v, order)),
            NpyData::F64(v) => NpyData::F64(pick(&v, order)),
            NpyData::U8(v) => NpyData::U8(pick(&v, order)),
        }
    }
}

/// The C-order position of each element of an array of `shape` stored in Fortran order.
fn fortran_to_c(shape: &[usize]) -> Vec<usize> {
    let count: usize = shape.iter().product();
    let mut strides = vec![1; shape.len()];
    for d in 1..shape.len() {
        strides[d] = strides[d - 1] * shape[d - 1];
    }
    (0..count)
        .map(|c| {
            // The C-order index `c` as a multi-index, last axis fastest, then its Fortran offset.
            let mut rest = c;
            let mut offset = 0;
            for d in (0..shape.len()).rev() {
                offset += (rest % shape[d]) * strides[d];
                rest /= shape[d];
            }
            offset
        })
        .collect()
}

fn parse(bytes: &[u8]) -> std::result::Result<NpyArray, String> {
    let (header, data) = split_header(bytes)?;
    let (descr, fortran, shape) = parse_header(header)?;
    let (scalar, big_endian) = element(&descr)?;
    check_data_length(&descr, &shape, data.len())?;
    let data = match scalar {
        Scalar::F32 => NpyData::F32(
            data.chunks_exact(4)
                .map(|c| {
                    let b = [c[0], c[1], c[2], c[3]];
                    if big_endian {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    }
                })
                .collect(),
        ),
        Scalar::U8 => NpyData::U8(data.to_vec()),
        _ => NpyData::F64(data.chunks_exact(scalar.size()).map(|c| scalar.decode(c, big_endian)).collect()),
    };
    // Fortran order stores the first axis fastest: taken back into C order.
    let data = if fortran { data.reordered(&fortran_to_c(&shape)) } else { data };
    Ok(NpyArray { shape, data })
}
