//! Minimal numpy `.npy` (format 1.0, `uint8`, C order) and `.npz` (deflate zip) support: the
//! two texture files of a model folder, written as `numpy.savez_compressed` writes them and
//! read with every size checked before allocating.

use super::ModelFileError;
use std::io::{Cursor, Read, Write};
use std::path::Path;
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipArchive, ZipWriter};

const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// Largest `.npy` header we accept (numpy itself writes 118 bytes for our arrays).
const MAX_HEADER: usize = 4096;

/// The `.npy` v1.0 bytes of a C-order `uint8` array of `shape`. The header is padded with
/// spaces and ends with `\n` so that the data starts at a multiple of 64 bytes (numpy ≥ 1.18).
pub(crate) fn npy_u8(shape: &[usize], data: &[u8]) -> Vec<u8> {
    debug_assert_eq!(shape.iter().product::<usize>(), data.len());
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '|u1', 'fortran_order': False, 'shape': {tuple}, }}");
    let unpadded = MAGIC.len() + 2 + 2 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// A zip archive with one deflated member `name` (e.g. `texture_alpha.npy`) holding `npy`, with
/// a fixed timestamp (1980-01-01) so that equal arrays give equal bytes.
pub(crate) fn npz_bytes(name: &str, npy: &[u8]) -> Result<Vec<u8>, zip::result::ZipError> {
    let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
    let options = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Deflated)
        .last_modified_time(DateTime::default())
        .unix_permissions(0o644);
    zip.start_file(name, options)?;
    zip.write_all(npy)?;
    Ok(zip.finish()?.into_inner())
}

/// Reads member `member` of the npz `bytes` (file `path`, for errors) as a `uint8` array whose
/// shape must equal `expected`; returns the data.
pub(crate) fn read_npz_u8(
    path: &Path,
    bytes: &[u8],
    member: &str,
    expected: &[usize],
) -> Result<Vec<u8>, ModelFileError> {
    let bad = |reason: String| ModelFileError::Npz {
        path: path.to_path_buf(),
        reason,
    };
    let mut archive = ZipArchive::new(Cursor::new(bytes)).map_err(|e| bad(format!("not a readable zip: {e}")))?;
    let mut entry = archive.by_name(member).map_err(|e| match e {
        zip::result::ZipError::FileNotFound => bad(format!("no array {member:?} in the archive")),
        e => bad(format!("cannot open {member}: {e}")),
    })?;
    let data_len: usize = expected.iter().product();
    // Read at most what a well-formed file can hold, plus one byte to detect excess.
    let limit = (10 + MAX_HEADER + data_len + 1) as u64;
    let mut npy = Vec::new();
    (&mut entry)
        .take(limit)
        .read_to_end(&mut npy)
        .map_err(|e| bad(format!("cannot decompress {member}: {e}")))?;
    drop(entry);
    let (shape, offset) = parse_npy_header(&npy).map_err(|r| bad(format!("{member}: {r}")))?;
    if shape != expected {
        return Err(ModelFileError::Shape {
            path: path.to_path_buf(),
            array: member.to_string(),
            found: shape,
            expected: expected.to_vec(),
        });
    }
    let body = &npy[offset..];
    if body.len() != data_len {
        return Err(bad(format!(
            "{member}: {} data bytes for shape {shape:?}, expected {data_len}",
            body.len()
        )));
    }
    Ok(body.to_vec())
}

/// Parses a `.npy` header (versions 1.0-3.0) of a C-order `uint8` array: the shape and the
/// offset of the data.
pub(crate) fn parse_npy_header(npy: &[u8]) -> Result<(Vec<usize>, usize), String> {
    if npy.len() < 10 || &npy[..6] != MAGIC {
        return Err("not a .npy array (bad magic)".into());
    }
    let (len, start) = match npy[6] {
        1 => (u16::from_le_bytes([npy[8], npy[9]]) as usize, 10),
        2 | 3 if npy.len() >= 12 => (u32::from_le_bytes([npy[8], npy[9], npy[10], npy[11]]) as usize, 12),
        v => return Err(format!("unsupported .npy version {v}.{}", npy[7])),
    };
    if len > MAX_HEADER || start + len > npy.len() {
        return Err(format!("header of {len} bytes does not fit"));
    }
    let header = std::str::from_utf8(&npy[start..start + len]).map_err(|_| "header is not text".to_string())?;
    let value = |key: &str| -> Result<&str, String> {
        let k = header
            .find(&format!("'{key}':"))
            .ok_or_else(|| format!("header has no '{key}'"))?;
        Ok(header[k + key.len() + 3..].trim_start())
    };
    let descr = value("descr")?;
    if !(descr.starts_with("'|u1'") || descr.starts_with("'<u1'") || descr.starts_with("'u1'")) {
        let end = descr.find(',').unwrap_or(descr.len());
        return Err(format!("dtype {} is not uint8", &descr[..end]));
    }
    if !value("fortran_order")?.starts_with("False") {
        return Err("Fortran-order arrays are not supported".into());
    }
    let shape = value("shape")?;
    let close = shape.find(')').ok_or("unterminated shape")?;
    if !shape.starts_with('(') {
        return Err("shape is not a tuple".into());
    }
    let dims: Result<Vec<usize>, String> = shape[1..close]
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| format!("bad dimension {s:?}")))
        .collect();
    Ok((dims?, start + len))
}
