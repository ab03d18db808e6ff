//! A small PLY point-cloud reader (for nerfstudio's `ply_file_path`).
//!
//! Reads the `vertex` element of ASCII, binary little-endian and binary big-endian PLY files:
//! positions from the `x y z` properties (any numeric type) and colours from `red green blue`
//! when present (integer types are divided by their maximum, 255 for `uchar`; float colours
//! are taken as they are and clamped to `[0, 1]`). Without colour properties every point is
//! mid-grey `[0.5, 0.5, 0.5]`. Other elements and properties (including lists) are skipped. In
//! ASCII files each element instance must be on its own line.
//!
//! ```
//! use bbsplat::scene::ply::parse_point_cloud;
//! use std::path::Path;
//! let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
//!             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
//!             end_header\n1 2 3 255 0 51\n";
//! let cloud = parse_point_cloud(text.as_bytes(), Path::new("points.ply")).unwrap();
//! assert_eq!(cloud.positions[0], glam::Vec3::new(1.0, 2.0, 3.0));
//! assert_eq!(cloud.colours[0], [1.0, 0.0, 0.2]);
//! ```

use super::PointCloud;
use super::error::{Location, SceneError};
use glam::Vec3;
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
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

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The value that maps to colour 1.0.
    fn colour_max(self) -> f64 {
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

    fn read(self, b: &[u8], little: bool) -> f64 {
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

#[derive(Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for a list property.
    list: Option<Scalar>,
    kind: Scalar,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// Parses a PLY file's bytes into a point cloud. `file` is only used in error messages.
pub fn parse_point_cloud(bytes: &[u8], file: &Path) -> Result<PointCloud, SceneError> {
    let perr = |loc: Location, m: String| SceneError::parse(file, loc, m);
    // Header: lines up to `end_header`.
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(perr(
                Location::Line(line_no + 1),
                "file ends inside the header (no end_header line)".into(),
            ));
        };
        line_no += 1;
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| perr(Location::Line(line_no), "header line is not valid UTF-8".into()))?
            .trim();
        let at = Location::Line(line_no);
        let toks: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if line != "ply" {
                return Err(perr(
                    at,
                    format!("not a PLY file: first line is {line:?}, expected \"ply\""),
                ));
            }
            continue;
        }
        match toks.first().copied() {
            Some("format") => {
                encoding = Some(match toks.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Little,
                    Some("binary_big_endian") => Encoding::Big,
                    other => return Err(perr(at, format!("unknown PLY format {other:?}"))),
                });
            }
            Some("element") => {
                let (Some(name), Some(count)) = (toks.get(1), toks.get(2).and_then(|c| c.parse::<usize>().ok())) else {
                    return Err(perr(at, format!("malformed element line {line:?}")));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(perr(at, "property before any element".into()));
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
                        _ => return Err(perr(at, format!("malformed list property {line:?}"))),
                    }
                } else {
                    match (toks.get(1).and_then(|t| Scalar::parse(t)), toks.get(2)) {
                        (Some(k), Some(n)) => Property {
                            name: n.to_string(),
                            list: None,
                            kind: k,
                        },
                        _ => return Err(perr(at, format!("malformed property {line:?}"))),
                    }
                };
                element.properties.push(property);
            }
            Some("end_header") => break,
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return Err(perr(at, format!("unknown header keyword {other:?}"))),
        }
    }
    let Some(encoding) = encoding else {
        return Err(perr(Location::Line(line_no), "the header has no format line".into()));
    };
    let Some(vi) = elements.iter().position(|e| e.name == "vertex") else {
        return Err(perr(Location::File, "no vertex element".into()));
    };
    let vertex = &elements[vi];
    let find = |n: &str| vertex.properties.iter().position(|p| p.name == n && p.list.is_none());
    let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
        return Err(perr(
            Location::File,
            "the vertex element lacks an x, y or z property".into(),
        ));
    };
    let colour = match (find("red"), find("green"), find("blue")) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    let mut cloud = PointCloud::default();
    let finish_vertex = |values: &[f64], cloud: &mut PointCloud| -> Result<(), String> {
        let p = Vec3::new(values[ix] as f32, values[iy] as f32, values[iz] as f32);
        if !p.is_finite() {
            return Err(format!(
                "position ({}, {}, {}) is not finite",
                values[ix], values[iy], values[iz]
            ));
        }
        cloud.positions.push(p);
        cloud.colours.push(match colour {
            Some(c) => c.map(|i| {
                let v = values[i] / vertex.properties[i].kind.colour_max();
                if v.is_finite() { v.clamp(0.0, 1.0) as f32 } else { 0.5 }
            }),
            None => [0.5; 3],
        });
        Ok(())
    };
    if encoding == Encoding::Ascii {
        let text = std::str::from_utf8(&bytes[pos..])
            .map_err(|_| perr(Location::Line(line_no + 1), "ASCII body is not valid UTF-8".into()))?;
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        for element in &elements[..=vi] {
            for k in 0..element.count {
                let Some((ln, l)) = lines.next() else {
                    return Err(perr(
                        Location::File,
                        format!("file ends after {k} of {} {} records", element.count, element.name),
                    ));
                };
                if element.name != "vertex" {
                    continue;
                }
                let at = Location::Line(line_no + 1 + ln);
                let values = l
                    .split_whitespace()
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|_| perr(at.clone(), format!("vertex {k}: not a list of numbers")))?;
                if values.len() < vertex.properties.len() || vertex.properties.iter().any(|p| p.list.is_some()) {
                    return Err(perr(
                        at,
                        format!(
                            "vertex {k}: expected {} values, found {}",
                            vertex.properties.len(),
                            values.len()
                        ),
                    ));
                }
                finish_vertex(&values, &mut cloud).map_err(|m| perr(at, format!("vertex {k}: {m}")))?;
            }
        }
        return Ok(cloud);
    }
    let little = encoding == Encoding::Little;
    for element in &elements[..=vi] {
        let min_size: usize = element.properties.iter().map(|p| p.list.unwrap_or(p.kind).size()).sum();
        if (element.count as u128) * (min_size as u128) > (bytes.len() - pos) as u128 {
            return Err(perr(
                Location::Binary {
                    record: format!("{} element", element.name),
                    offset: pos as u64,
                },
                format!(
                    "the header says {} {} records follow but only {} bytes remain",
                    element.count,
                    element.name,
                    bytes.len() - pos
                ),
            ));
        }
        let mut values = vec![0.0; element.properties.len()];
        for k in 0..element.count {
            let at = pos;
            let short = || {
                perr(
                    Location::Binary {
                        record: format!("{} {k}", element.name),
                        offset: at as u64,
                    },
                    "file ends inside the record".into(),
                )
            };
            for (pi, p) in element.properties.iter().enumerate() {
                let n = match p.list {
                    Some(c) => {
                        let b = bytes.get(pos..pos + c.size()).ok_or_else(short)?;
                        pos += c.size();
                        let n = c.read(b, little);
                        if !(0.0..=1e9).contains(&n) {
                            return Err(perr(
                                Location::Binary {
                                    record: format!("{} {k}", element.name),
                                    offset: at as u64,
                                },
                                format!("list length {n} is invalid"),
                            ));
                        }
                        n as usize
                    }
                    None => 1,
                };
                let size = n.checked_mul(p.kind.size()).ok_or_else(short)?;
                let b = bytes.get(pos..pos.saturating_add(size)).ok_or_else(short)?;
                if p.list.is_none() {
                    values[pi] = p.kind.read(b, little);
                }
                pos += size;
            }
            if element.name == "vertex" {
                finish_vertex(&values, &mut cloud).map_err(|m| {
                    perr(
                        Location::Binary {
                            record: format!("vertex {k}"),
                            offset: at as u64,
                        },
                        m,
                    )
                })?;
            }
        }
    }
    Ok(cloud)
}
