//! A reader of safetensors files holding `F32` tensors: an unsigned 64-bit little-endian header
//! length `n`, `n` bytes of JSON (an object: each tensor's name maps to its `dtype`, `shape` and
//! `data_offsets` `[begin, end)` into the data that follows the header; the optional
//! `__metadata__` maps strings to strings), then the tensors' raw bytes, little-endian.
//!
//! ```
//! use bbsplat::lpips::safetensors::parse;
//! let header = br#"{"w":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}}"#;
//! let mut file = (header.len() as u64).to_le_bytes().to_vec();
//! file.extend_from_slice(header);
//! file.extend_from_slice(&[0, 0, 128, 63, 0, 0, 0, 64]); // 1.0, 2.0
//! let tensors = parse(&file).unwrap();
//! assert_eq!(tensors["w"].shape, vec![2]);
//! assert_eq!(tensors["w"].values, vec![1.0, 2.0]);
//! ```

use std::collections::BTreeMap;

/// One tensor: its shape (outermost first) and its values in row-major order.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    /// Sizes of its axes, outermost first.
    pub shape: Vec<usize>,
    /// `shape`'s product of values, row-major.
    pub values: Vec<f32>,
    /// Its bytes' offset in the data section (for checksums in file order).
    pub offset: usize,
}

/// The largest header read: 100 MB (the format's own reference reader's limit).
const MAX_HEADER: u64 = 100_000_000;

/// The tensors of a safetensors file, by name (`__metadata__` skipped).
///
/// # Errors
///
/// A message saying what is malformed: a short file, a header that is not a JSON object, a
/// tensor of another type than `F32`, offsets that do not match its shape or lie outside the data.
pub fn parse(bytes: &[u8]) -> Result<BTreeMap<String, Tensor>, String> {
    let len_bytes: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| format!("{} bytes, shorter than the 8-byte header length", bytes.len()))?;
    let header_len = u64::from_le_bytes(len_bytes);
    if header_len > MAX_HEADER || header_len > (bytes.len() - 8) as u64 {
        return Err(format!(
            "a header of {header_len} bytes in a file of {} bytes",
            bytes.len()
        ));
    }
    let header_end = 8 + header_len as usize;
    let header: serde_json::Value =
        serde_json::from_slice(&bytes[8..header_end]).map_err(|e| format!("the header is not JSON: {e}"))?;
    let entries = header.as_object().ok_or("the header is not a JSON object")?;
    let data = &bytes[header_end..];
    let mut out = BTreeMap::new();
    for (name, entry) in entries {
        if name == "__metadata__" {
            continue;
        }
        let dtype = entry.get("dtype").and_then(|d| d.as_str());
        if dtype != Some("F32") {
            return Err(format!("tensor {name}: dtype {dtype:?}, only F32 is read"));
        }
        let shape: Vec<usize> = entry
            .get("shape")
            .and_then(|s| s.as_array())
            .and_then(|s| s.iter().map(|d| d.as_u64().map(|d| d as usize)).collect())
            .ok_or_else(|| format!("tensor {name}: no shape (an array of sizes)"))?;
        let offsets: Vec<usize> = entry
            .get("data_offsets")
            .and_then(|s| s.as_array())
            .and_then(|s| s.iter().map(|d| d.as_u64().map(|d| d as usize)).collect())
            .filter(|o: &Vec<usize>| o.len() == 2)
            .ok_or_else(|| format!("tensor {name}: no data_offsets [begin, end]"))?;
        let count = shape
            .iter()
            .try_fold(1usize, |n, &d| n.checked_mul(d))
            .ok_or_else(|| format!("tensor {name}: shape {shape:?} overflows"))?;
        let (begin, end) = (offsets[0], offsets[1]);
        if begin > end || end > data.len() || end - begin != count.saturating_mul(4) {
            return Err(format!(
                "tensor {name}: data_offsets [{begin}, {end}) for shape {shape:?} (4 bytes a value) in {} bytes of data",
                data.len()
            ));
        }
        let values = data[begin..end]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        out.insert(
            name.clone(),
            Tensor {
                shape,
                values,
                offset: begin,
            },
        );
    }
    Ok(out)
}
