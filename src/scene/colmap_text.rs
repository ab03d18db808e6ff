//! COLMAP text sparse models (`cameras.txt`, `images.txt`, `points3D.txt`): parsers taking
//! `&str` and writers returning `String`.
//!
//! Format (the fields of the binary files, whitespace-separated, one record per line):
//! - `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS...` with `MODEL` a name such as
//!   `SIMPLE_RADIAL`.
//! - `images.txt`: two lines per image: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, then
//!   the keypoints `X Y POINT3D_ID ...` (`-1` for none). As in COLMAP's own reader, the line
//!   right after an image line is its keypoint line even when it is empty; a missing keypoint
//!   line at the end of the file or a comment in its place is read as no keypoints. The name is
//!   the rest of the line after `CAMERA_ID`, trimmed (so it may contain inner spaces).
//! - `points3D.txt`: `POINT3D_ID X Y Z R G B ERROR (IMAGE_ID POINT2D_IDX)...`.
//!
//! Lines starting with `#` (after optional whitespace) and blank lines are skipped (except the
//! keypoint line above). Windows line endings are accepted. Numbers are parsed with Rust's
//! parsers (which accept `nan`/`inf`; these are then refused where a finite value is needed);
//! MSVC's `nan(ind)` is accepted as NaN. Writers print floats in Rust's shortest round-trip
//! form, so write-then-read gives bit-identical values.
//!
//! ```
//! use bbsplat::scene::colmap_text::parse_cameras;
//! use std::path::Path;
//! let text = "# a comment\n\n1 PINHOLE 640 480 500 500 320 240\n";
//! let cams = parse_cameras(text, Path::new("cameras.txt")).unwrap();
//! assert_eq!(cams[0].params, vec![500.0, 500.0, 320.0, 240.0]);
//! let err = parse_cameras("1 FISHEYE 640 480 1 2 3\n", Path::new("cameras.txt")).unwrap_err();
//! assert!(err.to_string().starts_with("cameras.txt: line 1: unsupported camera model unknown model name \"FISHEYE\""));
//! ```

use super::colmap::{
    CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint3D, IdSet, Point2D, TrackElement, check_name,
};
use super::error::{Location, SceneError};
use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

/// Decodes a text file's bytes as UTF-8, a leading byte-order mark left out
/// ([`crate::file_io::without_bom`]); the error names the line of the first invalid byte.
pub fn decode_utf8<'a>(bytes: &'a [u8], file: &Path) -> Result<&'a str, SceneError> {
    let bytes = crate::file_io::without_bom(bytes);
    std::str::from_utf8(bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count();
        SceneError::parse(file, Location::Line(line), "text is not valid UTF-8")
    })
}

/// Data lines: `(1-based line number, trimmed text)`, skipping blank and comment lines.
fn is_skipped(line: &str) -> bool {
    line.is_empty() || line.starts_with('#')
}

/// Parses a number token, naming the field in the error.
fn num<T: FromStr>(tok: Option<&str>, what: &str, expect: &str) -> Result<T, String> {
    let tok = tok.ok_or_else(|| format!("line ends before {what}"))?;
    tok.parse()
        .map_err(|_| format!("{what}: expected {expect}, found {tok:?}"))
}

/// Parses a float token (accepting MSVC's `nan(ind)` spellings).
fn float(tok: Option<&str>, what: &str) -> Result<f64, String> {
    match tok {
        Some(t) if t.to_ascii_lowercase().starts_with("nan(") || t.to_ascii_lowercase().starts_with("-nan(") => {
            Ok(f64::NAN)
        }
        _ => num(tok, what, "a number"),
    }
}

/// Parses `cameras.txt`. `file` is only used in error messages.
pub fn parse_cameras(text: &str, file: &Path) -> Result<Vec<ColmapCamera>, SceneError> {
    let mut out = Vec::new();
    let mut ids = IdSet::new();
    for (ln, line) in text.lines().enumerate() {
        let line = line.trim();
        if is_skipped(line) {
            continue;
        }
        let at = Location::Line(ln + 1);
        let mut toks = line.split_whitespace();
        let cam = (|| -> Result<ColmapCamera, SceneError> {
            let e = |m: String| SceneError::parse(file, at.clone(), m);
            let id: u32 = num(toks.next(), "CAMERA_ID", "an unsigned 32-bit integer").map_err(e)?;
            let model_name = toks.next().ok_or_else(|| e("line ends before MODEL".into()))?;
            let model = CameraModel::from_name(model_name).map_err(|model| SceneError::UnsupportedCameraModel {
                file: file.to_path_buf(),
                location: at.clone(),
                model,
            })?;
            let width: u64 = num(toks.next(), "WIDTH", "a positive integer").map_err(e)?;
            let height: u64 = num(toks.next(), "HEIGHT", "a positive integer").map_err(e)?;
            let params = toks
                .by_ref()
                .enumerate()
                .map(|(k, t)| float(Some(t), &format!("parameter {k}")))
                .collect::<Result<Vec<_>, _>>()
                .map_err(e)?;
            let cam = ColmapCamera {
                id,
                model,
                width,
                height,
                params,
            };
            cam.check().and_then(|()| ids.insert("CAMERA_ID", id)).map_err(e)?;
            Ok(cam)
        })()?;
        out.push(cam);
    }
    Ok(out)
}

/// Parses `images.txt`. `file` is only used in error messages.
pub fn parse_images(text: &str, file: &Path) -> Result<Vec<ColmapImage>, SceneError> {
    let mut out = Vec::new();
    let mut ids = IdSet::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((ln, line)) = lines.next() {
        let line = line.trim();
        if is_skipped(line) {
            continue;
        }
        let e = |n: usize, m: String| SceneError::parse(file, Location::Line(n + 1), m);
        let mut toks = line.split_whitespace();
        let id: u32 = num(toks.next(), "IMAGE_ID", "an unsigned 32-bit integer").map_err(|m| e(ln, m))?;
        let mut v = [0.0; 7];
        for (x, name) in v.iter_mut().zip(["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"]) {
            *x = float(toks.next(), name).map_err(|m| e(ln, m))?;
        }
        let camera_id: u32 = num(toks.next(), "CAMERA_ID", "an unsigned 32-bit integer").map_err(|m| e(ln, m))?;
        // The name is the rest of the line: find where the tenth token starts.
        let name = rest_after_tokens(line, 9).unwrap_or("").to_string();
        if name.is_empty() {
            return Err(e(ln, "line ends before NAME (the image name is absent)".into()));
        }
        // The keypoint line.
        let mut points2d = Vec::new();
        let next_is_points = matches!(lines.peek(), Some((_, l)) if !l.trim().starts_with('#'));
        let points_line = if next_is_points { lines.next() } else { None };
        if let Some((pln, pline)) = points_line {
            let toks: Vec<&str> = pline.split_whitespace().collect();
            if !toks.len().is_multiple_of(3) {
                return Err(e(
                    pln,
                    format!(
                        "expected the keypoints of the image on line {} as triplets X Y POINT3D_ID, found {} values \
                         (is the keypoint line missing?)",
                        ln + 1,
                        toks.len()
                    ),
                ));
            }
            points2d.reserve(toks.len() / 3);
            for (k, t) in toks.chunks_exact(3).enumerate() {
                let x = float(Some(t[0]), &format!("X of keypoint {k}")).map_err(|m| e(pln, m))?;
                let y = float(Some(t[1]), &format!("Y of keypoint {k}")).map_err(|m| e(pln, m))?;
                let point3d_id: i64 =
                    num(Some(t[2]), &format!("POINT3D_ID of keypoint {k}"), "an integer").map_err(|m| e(pln, m))?;
                points2d.push(Point2D { xy: [x, y], point3d_id });
            }
        }
        let image = ColmapImage {
            id,
            qvec: [v[0], v[1], v[2], v[3]],
            tvec: [v[4], v[5], v[6]],
            camera_id,
            name,
            points2d,
        };
        image
            .check()
            .and_then(|()| ids.insert("IMAGE_ID", id))
            .map_err(|m| e(ln, m))?;
        out.push(image);
    }
    Ok(out)
}

/// The text after the first `n` whitespace-separated tokens, trimmed; `None` when there are
/// not more than `n` tokens.
fn rest_after_tokens(line: &str, n: usize) -> Option<&str> {
    let mut rest = line.trim_start();
    for _ in 0..n {
        let end = rest.find(char::is_whitespace)?;
        rest = rest[end..].trim_start();
    }
    let rest = rest.trim();
    (!rest.is_empty()).then_some(rest)
}

/// Parses `points3D.txt`. `file` is only used in error messages.
pub fn parse_points(text: &str, file: &Path) -> Result<Vec<ColmapPoint3D>, SceneError> {
    let mut out = Vec::new();
    let mut ids = IdSet::new();
    for (ln, line) in text.lines().enumerate() {
        let line = line.trim();
        if is_skipped(line) {
            continue;
        }
        let e = |m: String| SceneError::parse(file, Location::Line(ln + 1), m);
        let toks: Vec<&str> = line.split_whitespace().collect();
        let mut it = toks.iter().copied();
        let id: u64 = num(it.next(), "POINT3D_ID", "an unsigned integer").map_err(e)?;
        let mut xyz = [0.0; 3];
        for (v, name) in xyz.iter_mut().zip(["X", "Y", "Z"]) {
            *v = float(it.next(), name).map_err(e)?;
        }
        let mut rgb = [0u8; 3];
        for (v, name) in rgb.iter_mut().zip(["R", "G", "B"]) {
            *v = num(it.next(), name, "an integer in 0..=255").map_err(e)?;
        }
        let error = float(it.next(), "ERROR").map_err(e)?;
        let rest: Vec<&str> = it.collect();
        if !rest.len().is_multiple_of(2) {
            return Err(e(format!(
                "the track must be pairs IMAGE_ID POINT2D_IDX, found {} values",
                rest.len()
            )));
        }
        let track = rest
            .chunks_exact(2)
            .enumerate()
            .map(|(k, t)| {
                Ok(TrackElement {
                    image_id: num(
                        Some(t[0]),
                        &format!("IMAGE_ID of track element {k}"),
                        "an unsigned 32-bit integer",
                    )?,
                    point2d_idx: num(
                        Some(t[1]),
                        &format!("POINT2D_IDX of track element {k}"),
                        "an unsigned 32-bit integer",
                    )?,
                })
            })
            .collect::<Result<Vec<_>, String>>()
            .map_err(e)?;
        if xyz.iter().any(|v| !v.is_finite()) {
            return Err(e(format!("position {xyz:?} is not finite")));
        }
        ids.insert("POINT3D_ID", id).map_err(e)?;
        out.push(ColmapPoint3D {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    Ok(out)
}

/// Serialises cameras in the `cameras.txt` layout (with COLMAP's header comments).
pub fn write_cameras(cameras: &[ColmapCamera]) -> String {
    let mut s = String::new();
    s.push_str("# Camera list with one line of data per camera:\n");
    s.push_str("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let _ = writeln!(s, "# Number of cameras: {}", cameras.len());
    for c in cameras {
        let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for p in &c.params {
            let _ = write!(s, " {p:?}");
        }
        s.push('\n');
    }
    s
}

/// Serialises images in the `images.txt` layout. Fails (naming the record) when a name cannot
/// be represented in the text format (empty, line breaks, leading/trailing whitespace).
pub fn write_images(images: &[ColmapImage]) -> Result<String, SceneError> {
    let mut s = String::new();
    s.push_str("# Image list with two lines of data per image:\n");
    s.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    s.push_str("#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let _ = writeln!(s, "# Number of images: {}", images.len());
    for (i, im) in images.iter().enumerate() {
        check_name(&im.name).map_err(|m| {
            SceneError::parse(
                Path::new("images.txt"),
                Location::Record(format!("image {i} (image_id {})", im.id)),
                format!("cannot write: {m}"),
            )
        })?;
        let [qw, qx, qy, qz] = im.qvec;
        let [tx, ty, tz] = im.tvec;
        let _ = writeln!(
            s,
            "{} {qw:?} {qx:?} {qy:?} {qz:?} {tx:?} {ty:?} {tz:?} {} {}",
            im.id, im.camera_id, im.name
        );
        let mut first = true;
        for p in &im.points2d {
            if !first {
                s.push(' ');
            }
            first = false;
            let _ = write!(s, "{:?} {:?} {}", p.xy[0], p.xy[1], p.point3d_id);
        }
        s.push('\n');
    }
    Ok(s)
}

/// Serialises 3D points in the `points3D.txt` layout.
pub fn write_points(points: &[ColmapPoint3D]) -> String {
    let mut s = String::new();
    s.push_str("# 3D point list with one line of data per point:\n");
    s.push_str("#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    let _ = writeln!(s, "# Number of points: {}", points.len());
    for p in points {
        let [x, y, z] = p.xyz;
        let [r, g, b] = p.rgb;
        let _ = write!(s, "{} {x:?} {y:?} {z:?} {r} {g} {b} {:?}", p.id, p.error);
        for t in &p.track {
            let _ = write!(s, " {} {}", t.image_id, t.point2d_idx);
        }
        s.push('\n');
    }
    s
}

/// Writes `cameras.txt`, `images.txt` and `points3D.txt` into `dir` (which must exist).
pub fn write_model(model: &ColmapModel, dir: &Path) -> Result<(), SceneError> {
    let files = [
        ("cameras.txt", write_cameras(&model.cameras)),
        ("images.txt", write_images(&model.images)?),
        ("points3D.txt", write_points(&model.points)),
    ];
    for (name, text) in files {
        let path = dir.join(name);
        crate::file_io::write_atomic(&path, text.as_bytes())?;
    }
    Ok(())
}
