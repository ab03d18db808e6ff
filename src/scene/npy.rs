//! A small reader of numpy `.npy` arrays (format versions 1.0, 2.0 and 3.0) and of `.npz`
//! archives (zip, stored or deflated), for the camera files of the NeuS/IDR and LLFF datasets.
//!
//! Supported arrays: C order, little-endian `float32` (`<f4`), `float64` (`<f8`) or `uint8`
//! (`|u1`); values are returned as `f64` (`float32` converted exactly). Everything else is a
//! typed [`NpyError`]: a bad magic string, an unknown version, a header that is not numpy's
//! dictionary, another dtype, big-endian data, Fortran order, a shape whose size overflows, and
//! data that is shorter (truncated) or longer than the shape says.
//!
//! ```
//! use bbsplat::scene::npy::{parse_npy, write_npy_f64};
//! let bytes = write_npy_f64(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
//! let array = parse_npy(&bytes).unwrap();
//! assert_eq!(array.shape, vec![2, 3]);
//! assert_eq!(array.data[5], 6.0);
//! assert!(parse_npy(&bytes[..bytes.len() - 1]).is_err()); // truncated
//! ```

use crate::zipfile::{Method, ZipArchive, ZipError, write_zip};
use std::collections::BTreeMap;

/// The magic string every `.npy` file starts with.
pub const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// Largest header accepted, bytes (numpy writes 64 to a few hundred).
pub const MAX_HEADER: usize = 65_536;
/// Largest total of decompressed member bytes read from one `.npz` archive (a zip bomb is
/// refused instead of filling memory).
pub const MAX_NPZ_BYTES: u64 = 1_000_000_000;

/// The element types read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `|u1`: 8-bit unsigned integers.
    U8,
    /// `<f4`: little-endian IEEE single precision.
    F32,
    /// `<f8`: little-endian IEEE double precision.
    F64,
}

impl Dtype {
    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::F32 => 4,
            Dtype::F64 => 8,
        }
    }
}

/// What is wrong with an `.npy` array or an `.npz` archive.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NpyError {
    /// The bytes do not start with `\x93NUMPY`.
    #[error("not a .npy array (bad magic: the file does not start with \\x93NUMPY)")]
    BadMagic,
    /// A format version other than 1.0, 2.0 or 3.0.
    #[error("unsupported .npy format version {0}.{1} (1.0, 2.0 and 3.0 are read)")]
    UnsupportedVersion(u8, u8),
    /// The header is cut short, too long, not text, or not numpy's dictionary.
    #[error("malformed .npy header: {0}")]
    BadHeader(String),
    /// A dtype this reader does not handle.
    #[error("unsupported dtype {0} (little-endian float32 '<f4', float64 '<f8' and uint8 '|u1' are read)")]
    UnsupportedDtype(String),
    /// Big-endian data.
    #[error("big-endian dtype {0} is not supported (save the array little-endian)")]
    BigEndian(String),
    /// Fortran (column-major) order.
    #[error("Fortran-order arrays are not supported (save the array in C order)")]
    FortranOrder,
    /// Fewer data bytes than the shape needs.
    #[error("truncated data: shape {shape:?} of {dtype:?} needs {expected} bytes, the file holds {found}")]
    Truncated {
        /// The shape in the header.
        shape: Vec<usize>,
        /// The element type.
        dtype: Dtype,
        /// Bytes the shape needs.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// More data bytes than the shape needs, or a shape whose size overflows.
    #[error("size mismatch: shape {shape:?} of {dtype:?} needs {expected} bytes, the file holds {found}")]
    SizeMismatch {
        /// The shape in the header.
        shape: Vec<usize>,
        /// The element type.
        dtype: Dtype,
        /// Bytes the shape needs (`u64::MAX` when it overflows).
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// An array has another shape than the one its reader needs.
    #[error("shape {found:?}, expected {expected}")]
    Shape {
        /// The shape found.
        found: Vec<usize>,
        /// The shape needed, in words (e.g. `"(4, 4)"`, `"(N, 17)"`).
        expected: String,
    },
    /// The `.npz` archive is not a readable zip, or a member cannot be decompressed.
    #[error("not a readable .npz (zip) archive: {0}")]
    Zip(String),
    /// The members of an `.npz` decompress to more than [`MAX_NPZ_BYTES`].
    #[error("the archive's arrays decompress to more than {MAX_NPZ_BYTES} bytes")]
    TooLarge,
}

/// The parsed header of an `.npy` array.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NpyHeader {
    /// The element type.
    pub dtype: Dtype,
    /// The shape (C order); `[]` for a scalar.
    pub shape: Vec<usize>,
    /// Offset of the first data byte from the start of the file.
    pub data_offset: usize,
}

/// An array read as `f64` values, C order (the last index varies fastest).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values.
    pub data: Vec<f64>,
}

/// The value of `key` in numpy's header dictionary (the text after `'key':`).
fn header_value<'a>(header: &'a str, key: &str) -> Result<&'a str, NpyError> {
    let pattern = format!("'{key}':");
    let at = header
        .find(&pattern)
        .ok_or_else(|| NpyError::BadHeader(format!("no '{key}' entry")))?;
    Ok(header[at + pattern.len()..].trim_start())
}

/// Parses the dtype string (quoted, e.g. `'<f8'`) at the start of `value`.
fn parse_dtype(value: &str) -> Result<Dtype, NpyError> {
    let quote = value.chars().next().filter(|c| *c == '\'' || *c == '"');
    let Some(quote) = quote else {
        return Err(NpyError::UnsupportedDtype(
            value.split(',').next().unwrap_or("").trim().to_string(),
        ));
    };
    let rest = &value[1..];
    let end = rest
        .find(quote)
        .ok_or_else(|| NpyError::BadHeader("unterminated 'descr'".into()))?;
    let descr = &rest[..end];
    match descr {
        "<f8" => Ok(Dtype::F64),
        "<f4" => Ok(Dtype::F32),
        // One byte has no byte order: numpy writes `|u1`, and reads the others the same.
        "|u1" | "<u1" | ">u1" | "u1" => Ok(Dtype::U8),
        d if d.starts_with('>') => Err(NpyError::BigEndian(format!("'{d}'"))),
        d => Err(NpyError::UnsupportedDtype(format!("'{d}'"))),
    }
}

/// Parses the shape tuple at the start of `value`, e.g. `(20, 17)`, `(3,)` or `()`.
fn parse_shape(value: &str) -> Result<Vec<usize>, NpyError> {
    if !value.starts_with('(') {
        return Err(NpyError::BadHeader("'shape' is not a tuple".into()));
    }
    let close = value
        .find(')')
        .ok_or_else(|| NpyError::BadHeader("unterminated 'shape'".into()))?;
    value[1..close]
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.trim_end_matches('L')
                .parse::<usize>()
                .map_err(|_| NpyError::BadHeader(format!("bad dimension {s:?} in 'shape'")))
        })
        .collect()
}

/// Parses the header of an `.npy` file: magic, version, header length, then numpy's dictionary
/// with `descr`, `fortran_order` and `shape`.
///
/// # Errors
/// [`NpyError`] for anything but a C-order little-endian `f4`/`f8`/`u1` array header.
pub fn parse_header(npy: &[u8]) -> Result<NpyHeader, NpyError> {
    if npy.len() < MAGIC.len() || &npy[..MAGIC.len()] != MAGIC {
        return Err(NpyError::BadMagic);
    }
    if npy.len() < 10 {
        return Err(NpyError::BadHeader(format!("the file ends after {} bytes", npy.len())));
    }
    let (len, start) = match npy[6] {
        1 => (u16::from_le_bytes([npy[8], npy[9]]) as usize, 10),
        2 | 3 if npy.len() >= 12 => (u32::from_le_bytes([npy[8], npy[9], npy[10], npy[11]]) as usize, 12),
        2 | 3 => return Err(NpyError::BadHeader(format!("the file ends after {} bytes", npy.len()))),
        v => return Err(NpyError::UnsupportedVersion(v, npy[7])),
    };
    if len > MAX_HEADER {
        return Err(NpyError::BadHeader(format!(
            "a header of {len} bytes is longer than {MAX_HEADER}"
        )));
    }
    if start + len > npy.len() {
        return Err(NpyError::BadHeader(format!(
            "a header of {len} bytes does not fit in the {} bytes of the file",
            npy.len()
        )));
    }
    let header = std::str::from_utf8(&npy[start..start + len])
        .map_err(|_| NpyError::BadHeader("the header is not UTF-8 text".into()))?;
    if !header.trim_start().starts_with('{') {
        return Err(NpyError::BadHeader("the header is not a dictionary".into()));
    }
    let dtype = parse_dtype(header_value(header, "descr")?)?;
    let order = header_value(header, "fortran_order")?;
    if order.starts_with("True") {
        return Err(NpyError::FortranOrder);
    }
    if !order.starts_with("False") {
        return Err(NpyError::BadHeader("'fortran_order' is neither True nor False".into()));
    }
    let shape = parse_shape(header_value(header, "shape")?)?;
    Ok(NpyHeader {
        dtype,
        shape,
        data_offset: start + len,
    })
}

/// Parses a whole `.npy` file into `f64` values, the data length checked against the shape.
///
/// # Errors
/// As [`parse_header`], and [`NpyError::Truncated`] / [`NpyError::SizeMismatch`] when the data
/// is shorter / longer than the shape needs.
pub fn parse_npy(npy: &[u8]) -> Result<NpyArray, NpyError> {
    let header = parse_header(npy)?;
    let body = &npy[header.data_offset..];
    let found = body.len() as u64;
    let count = header.shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    let expected = count.and_then(|c| c.checked_mul(header.dtype.size()));
    let Some(expected) = expected else {
        return Err(NpyError::SizeMismatch {
            shape: header.shape,
            dtype: header.dtype,
            expected: u64::MAX,
            found,
        });
    };
    if body.len() != expected {
        let (shape, dtype, expected) = (header.shape, header.dtype, expected as u64);
        return Err(if found < expected {
            NpyError::Truncated {
                shape,
                dtype,
                expected,
                found,
            }
        } else {
            NpyError::SizeMismatch {
                shape,
                dtype,
                expected,
                found,
            }
        });
    }
    let data = match header.dtype {
        Dtype::U8 => body.iter().map(|&b| b as f64).collect(),
        Dtype::F32 => body
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect(),
        Dtype::F64 => body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect(),
    };
    Ok(NpyArray {
        shape: header.shape,
        data,
    })
}

/// The members of an `.npz` archive, undecoded: name (without `.npy`) to the member's bytes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Npz {
    members: BTreeMap<String, Vec<u8>>,
}

impl Npz {
    /// Reads every member of the zip archive `bytes` (at most [`MAX_NPZ_BYTES`] decompressed in
    /// all). Member names lose a trailing `.npy`, as `numpy.load` names them.
    ///
    /// # Errors
    /// [`NpyError::Zip`] for an unreadable archive or member, [`NpyError::TooLarge`].
    pub fn parse(bytes: &[u8]) -> Result<Npz, NpyError> {
        let archive = ZipArchive::parse(bytes).map_err(|e| NpyError::Zip(e.to_string()))?;
        let mut members = BTreeMap::new();
        let mut budget = MAX_NPZ_BYTES;
        for name in archive.names().filter(|n| !n.ends_with('/')) {
            let data = archive.read(name, budget).map_err(|e| match e {
                ZipError::TooLarge { .. } => NpyError::TooLarge,
                e => NpyError::Zip(e.to_string()),
            })?;
            budget -= data.len() as u64;
            let key = name.strip_suffix(".npy").unwrap_or(name).to_string();
            members.entry(key).or_insert(data);
        }
        Ok(Npz { members })
    }

    /// The member names (without `.npy`), in name order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.members.keys().map(String::as_str)
    }

    /// Whether the archive holds member `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.members.contains_key(name)
    }

    /// Member `name` parsed ([`parse_npy`]), or `None` when the archive has no such member.
    ///
    /// # Errors
    /// As [`parse_npy`].
    pub fn array(&self, name: &str) -> Option<Result<NpyArray, NpyError>> {
        self.members.get(name).map(|b| parse_npy(b))
    }
}

/// The `.npy` v1.0 bytes of a C-order little-endian `float64` array (as `numpy.save` writes
/// it: the header padded with spaces to a multiple of 64 bytes and ended by `\n`). For tests,
/// fuzzing and tools that write datasets.
pub fn write_npy_f64(shape: &[usize], data: &[f64]) -> Vec<u8> {
    let body: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    write_npy_raw("<f8", shape, &body)
}

/// The `.npy` v1.0 bytes of an array of dtype `descr` (e.g. `"<f4"`, `"|u1"`, or any string,
/// for tests of refused dtypes) whose data bytes are `body`, unchecked against the shape.
pub fn write_npy_raw(descr: &str, shape: &[usize], body: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {tuple}, }}");
    let unpadded = MAGIC.len() + 2 + 2 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + body.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(body);
    out
}

/// A stored (uncompressed) zip archive of `members` (name, bytes), names written as given
/// (give them `.npy`), as `numpy.savez` writes it. For tests, fuzzing and tools.
///
/// # Errors
/// [`ZipError::Unwritable`] for a name or size past the zip format's fields
/// ([`crate::zipfile::write_zip`]).
pub fn write_npz(members: &[(&str, Vec<u8>)]) -> Result<Vec<u8>, ZipError> {
    let refs: Vec<(&str, &[u8])> = members.iter().map(|(n, b)| (*n, b.as_slice())).collect();
    write_zip(&refs, Method::Stored)
}
