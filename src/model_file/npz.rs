//! Minimal numpy `.npy` (format 1.0, `uint8`, C order) and `.npz` (deflate zip, [`crate::zipfile`]) support: the
//! two texture files of a model folder, written as `numpy.savez_compressed` writes them and
//! read with every size checked before allocating.

use super::ModelFileError;
use crate::zipfile::{Method, ZipArchive, ZipError, write_zip};
use std::path::Path;

/// Largest `.npy` header we accept (numpy itself writes 118 bytes for our arrays).
const MAX_HEADER: usize = 4096;

/// The `.npy` v1.0 bytes of a C-order `uint8` array of `shape`. The header is padded with
/// spaces and ends with `\n` so that the data starts at a multiple of 64 bytes (numpy ≥ 1.18);
/// the writer is [`crate::scene::npy::write_npy_raw`].
pub(crate) fn npy_u8(shape: &[usize], data: &[u8]) -> Vec<u8> {
    debug_assert_eq!(shape.iter().product::<usize>(), data.len());
    crate::scene::npy::write_npy_raw("|u1", shape, data)
}

/// A zip archive with one deflated member `name` (e.g. `texture_alpha.npy`) holding `npy`, with
/// a fixed timestamp (1980-01-01) so that equal arrays give equal bytes ([`crate::zipfile`]).
pub(crate) fn npz_bytes(name: &str, npy: &[u8]) -> Result<Vec<u8>, ZipError> {
    write_zip(&[(name, npy)], Method::Deflated)
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
    let archive = ZipArchive::parse(bytes).map_err(|e| bad(e.to_string()))?;
    let data_len: usize = expected.iter().product();
    // At most what a well-formed file of this shape can hold.
    let limit = (10 + MAX_HEADER + data_len) as u64;
    let npy = archive.read(member, limit).map_err(|e| match e {
        ZipError::NotFound(_) => bad(format!("no array {member:?} in the archive")),
        ZipError::TooLarge { size, .. } => {
            // Too long for this shape: its header says which shape it holds.
            let shape = archive
                .read_prefix(member, 10 + MAX_HEADER)
                .ok()
                .and_then(|head| parse_npy_header(&head).ok())
                .map(|(shape, _)| shape);
            match shape {
                Some(found) if found != expected => ModelFileError::Shape {
                    path: path.to_path_buf(),
                    array: member.to_string(),
                    found,
                    expected: expected.to_vec(),
                },
                _ => bad(format!(
                    "{member} holds {size} bytes, more than an array of shape {expected:?} needs"
                )),
            }
        }
        e => bad(format!("cannot read {member}: {e}")),
    })?;
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
/// offset of the data. The parser is [`crate::scene::npy::parse_header`]; other dtypes are
/// refused here.
pub(crate) fn parse_npy_header(npy: &[u8]) -> Result<(Vec<usize>, usize), String> {
    let header = crate::scene::npy::parse_header(npy).map_err(|e| e.to_string())?;
    if header.dtype != crate::scene::npy::Dtype::U8 {
        return Err(format!("dtype {:?} is not uint8", header.dtype));
    }
    if header.data_offset > 10 + MAX_HEADER {
        return Err(format!("header of {} bytes is too long", header.data_offset - 10));
    }
    Ok((header.shape, header.data_offset))
}
