//! The PLY layout: header (format, elements, typed properties) and the records of the body, in
//! ASCII, binary little-endian and binary big-endian. The one PLY reader of the crate: point
//! clouds ([`super::parse_point_cloud`]) and model files (`model_file::ply`) read the header and
//! the records with it and keep their own field mapping and errors.
//!
//! Errors are [`PlyError`]s: a [`Location`] in the file (a 1-based header or ASCII line, a binary
//! record and byte offset, or the whole file) and a message; callers attach the file's path.
//!
//! ```
//! use bbsplat::scene::ply::layout::{Encoding, Scalar, read_element, read_header};
//! let text = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty uchar red\nend_header\n1 2\n3 4\n";
//! let header = read_header(text).unwrap();
//! assert_eq!((header.encoding, header.version.as_str()), (Encoding::Ascii, "1.0"));
//! let vertex = &header.elements[0];
//! assert_eq!((vertex.name.as_str(), vertex.count), ("vertex", 2));
//! assert_eq!(vertex.properties[1].kind, Scalar::U8);
//! let mut rows = Vec::new();
//! read_element(text, &header, 0, |_, values| {
//!     rows.push(values.to_vec());
//!     Ok(())
//! })
//! .unwrap();
//! assert_eq!(rows, [[1.0, 2.0], [3.0, 4.0]]);
//! ```

use crate::scene::Location;

/// A scalar property type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    /// `char` / `int8`.
    I8,
    /// `uchar` / `uint8`.
    U8,
    /// `short` / `int16`.
    I16,
    /// `ushort` / `uint16`.
    U16,
    /// `int` / `int32`.
    I32,
    /// `uint` / `uint32`.
    U32,
    /// `float` / `float32`.
    F32,
    /// `double` / `float64`.
    F64,
}

impl Scalar {
    /// The type of a header type name (either spelling), `None` for an unknown name.
    pub fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The classic header name (`uchar`, `float`, `double`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// Bytes of one value in a binary body.
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The largest value of an integer type (1 for the float types).
    pub fn integer_max(self) -> f64 {
        match self {
            Scalar::I8 => 127.0,
            Scalar::U8 => 255.0,
            Scalar::I16 => 32767.0,
            Scalar::U16 => 65535.0,
            Scalar::I32 => 2147483647.0,
            Scalar::U32 => 4294967295.0,
            Scalar::F32 | Scalar::F64 => 1.0,
        }
    }

    /// Decodes one value from the first [`size`](Self::size) bytes of `b`.
    ///
    /// # Panics
    /// When `b` is shorter than the type.
    pub fn read(self, b: &[u8], little: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if little {
                    <$t>::from_le_bytes(a) as f64
                } else {
                    <$t>::from_be_bytes(a) as f64
                }
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

/// One property of an element.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Property {
    /// Its name.
    pub name: String,
    /// `Some(count type)` for a list property.
    pub list: Option<Scalar>,
    /// The type of the value (of each list item for a list).
    pub kind: Scalar,
}

/// One element of the header: its name, record count and properties in file order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Element {
    /// Its name (`vertex`, `face`, ...).
    pub name: String,
    /// Number of records.
    pub count: usize,
    /// Properties, in file order.
    pub properties: Vec<Property>,
}

impl Element {
    /// Index of the scalar (non-list) property called `name`.
    pub fn scalar(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name && p.list.is_none())
    }
}

/// The body encoding of the `format` line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// `ascii`.
    Ascii,
    /// `binary_little_endian`.
    BinaryLittleEndian,
    /// `binary_big_endian`.
    BinaryBigEndian,
}

impl Encoding {
    /// The `format` line's name.
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLittleEndian => "binary_little_endian",
            Encoding::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// A parsed header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Header {
    /// The body encoding.
    pub encoding: Encoding,
    /// The format version (`1.0`; empty when the `format` line has none).
    pub version: String,
    /// The elements, in file order.
    pub elements: Vec<Element>,
    /// Lines of the header, `end_header` included.
    pub lines: usize,
    /// Byte offset of the body (just after the `end_header` line).
    pub body_start: usize,
}

impl Header {
    /// Index of the element called `name`.
    pub fn element(&self, name: &str) -> Option<usize> {
        self.elements.iter().position(|e| e.name == name)
    }
}

/// A problem in a PLY file: where and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyError {
    /// Where.
    pub location: Location,
    /// What is wrong.
    pub message: String,
}

fn err(location: Location, message: impl Into<String>) -> PlyError {
    PlyError {
        location,
        message: message.into(),
    }
}

/// Reads the header: the lines from `ply` to `end_header` (`comment` and `obj_info` lines are
/// skipped, blanks around words ignored).
pub fn read_header(bytes: &[u8]) -> Result<Header, PlyError> {
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(err(
                Location::Line(line_no + 1),
                "file ends inside the header (no end_header line)",
            ));
        };
        line_no += 1;
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| err(Location::Line(line_no), "header line is not valid UTF-8"))?
            .trim();
        let at = Location::Line(line_no);
        let toks: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if line != "ply" {
                return Err(err(
                    at,
                    format!("not a PLY file: first line is {line:?}, expected \"ply\""),
                ));
            }
            continue;
        }
        match toks.first().copied() {
            Some("format") => {
                let encoding = match toks.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::BinaryLittleEndian,
                    Some("binary_big_endian") => Encoding::BinaryBigEndian,
                    other => return Err(err(at, format!("unknown PLY format {other:?}"))),
                };
                format = Some((encoding, toks.get(2).copied().unwrap_or_default().to_string()));
            }
            Some("element") => {
                let (Some(name), Some(count)) = (toks.get(1), toks.get(2).and_then(|c| c.parse::<usize>().ok())) else {
                    return Err(err(at, format!("malformed element line {line:?}")));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(at, "property before any element"));
                };
                let property = if toks.get(1) == Some(&"list") {
                    match (
                        toks.get(2).and_then(|t| Scalar::parse(t)),
                        toks.get(3).and_then(|t| Scalar::parse(t)),
                        toks.get(4),
                    ) {
                        (Some(c), Some(k), Some(n)) => Property {
                            name: n.to_string(),
                            list: Some(c),
                            kind: k,
                        },
                        _ => return Err(err(at, format!("malformed list property {line:?}"))),
                    }
                } else {
                    match (toks.get(1).and_then(|t| Scalar::parse(t)), toks.get(2)) {
                        (Some(k), Some(n)) => Property {
                            name: n.to_string(),
                            list: None,
                            kind: k,
                        },
                        _ => return Err(err(at, format!("malformed property {line:?}"))),
                    }
                };
                element.properties.push(property);
            }
            Some("end_header") => break,
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return Err(err(at, format!("unknown header keyword {other:?}"))),
        }
    }
    let Some((encoding, version)) = format else {
        return Err(err(Location::Line(line_no), "the header has no format line"));
    };
    Ok(Header {
        encoding,
        version,
        elements,
        lines: line_no,
        body_start: pos,
    })
}

/// Reads the records of element `target` of `header` from the body of `bytes` (the elements
/// before it are skipped, the ones after it are not read): calls `visit(k, values)` for record
/// `k` with one value per property (lists are skipped and their value left 0; in ASCII files
/// an element with a list property is refused). An `Err(message)` of `visit` becomes a
/// [`PlyError`] at the record (`"{element} {k}: {message}"` on an ASCII line, record
/// `"{element} {k}"` in a binary body).
///
/// ASCII bodies hold one record per non-blank line.
///
/// # Panics
/// When `target` is not an element index of `header`.
pub fn read_element(
    bytes: &[u8],
    header: &Header,
    target: usize,
    mut visit: impl FnMut(usize, &[f64]) -> Result<(), String>,
) -> Result<(), PlyError> {
    let mut pos = header.body_start;
    let elements = &header.elements[..=target];
    if header.encoding == Encoding::Ascii {
        let text = std::str::from_utf8(&bytes[pos..])
            .map_err(|_| err(Location::Line(header.lines + 1), "ASCII body is not valid UTF-8"))?;
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        for (ei, e) in elements.iter().enumerate() {
            for k in 0..e.count {
                let Some((ln, l)) = lines.next() else {
                    return Err(err(
                        Location::File,
                        format!("file ends after {k} of {} {} records", e.count, e.name),
                    ));
                };
                if ei != target {
                    continue;
                }
                let at = Location::Line(header.lines + 1 + ln);
                let name = &e.name;
                let values = l
                    .split_whitespace()
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|_| err(at.clone(), format!("{name} {k}: not a list of numbers")))?;
                if values.len() < e.properties.len() || e.properties.iter().any(|p| p.list.is_some()) {
                    return Err(err(
                        at,
                        format!(
                            "{name} {k}: expected {} values, found {}",
                            e.properties.len(),
                            values.len()
                        ),
                    ));
                }
                visit(k, &values).map_err(|m| err(at, format!("{name} {k}: {m}")))?;
            }
        }
        return Ok(());
    }
    let little = header.encoding == Encoding::BinaryLittleEndian;
    for (ei, e) in elements.iter().enumerate() {
        if e.properties.is_empty() {
            // Records of no bytes: nothing to skip (a count of 10¹² is not 10¹² iterations), and
            // nothing to read if it is the target.
            if ei == target && e.count > 0 {
                return Err(err(
                    Location::Binary {
                        record: format!("{} element", e.name),
                        offset: pos as u64,
                    },
                    format!("{} {} records with no property", e.count, e.name),
                ));
            }
            continue;
        }
        let min_size: usize = e.properties.iter().map(|p| p.list.unwrap_or(p.kind).size()).sum();
        if (e.count as u128) * (min_size as u128) > (bytes.len() - pos) as u128 {
            return Err(err(
                Location::Binary {
                    record: format!("{} element", e.name),
                    offset: pos as u64,
                },
                format!(
                    "the header says {} {} records follow but only {} bytes remain",
                    e.count,
                    e.name,
                    bytes.len() - pos
                ),
            ));
        }
        let mut values = vec![0.0; e.properties.len()];
        for k in 0..e.count {
            let start = pos;
            let at = || Location::Binary {
                record: format!("{} {k}", e.name),
                offset: start as u64,
            };
            let short = || err(at(), "file ends inside the record");
            for (pi, p) in e.properties.iter().enumerate() {
                let n = match p.list {
                    Some(c) => {
                        let b = bytes.get(pos..pos + c.size()).ok_or_else(short)?;
                        pos += c.size();
                        let n = c.read(b, little);
                        if !(0.0..=1e9).contains(&n) {
                            return Err(err(at(), format!("list length {n} is invalid")));
                        }
                        n as usize
                    }
                    None => 1,
                };
                let size = n.checked_mul(p.kind.size()).ok_or_else(short)?;
                let b = bytes.get(pos..pos.saturating_add(size)).ok_or_else(short)?;
                if p.list.is_none() && ei == target {
                    values[pi] = p.kind.read(b, little);
                }
                pos += size;
            }
            if ei == target {
                visit(k, &values).map_err(|m| err(at(), m))?;
            }
        }
    }
    Ok(())
}
