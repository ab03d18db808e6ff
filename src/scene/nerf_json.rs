//! NeRF-synthetic (`transforms_{train,test}.json`) and instant-ngp / nerfstudio
//! (`transforms.json`) camera files.
//!
//! Both are JSON objects with scene-level intrinsics and a `frames` array. Each frame has a
//! `file_path` (relative to the JSON file's folder; without extension in NeRF-synthetic, where
//! `.png` is tried) and a `transform_matrix`: a **camera-to-world** matrix (4 rows of 4 numbers,
//! or 3 rows) in **OpenGL/Blender camera axes** (x right, y up, the camera looks along −z).
//!
//! Intrinsics, in pixels, are looked up per frame first, then at the scene level:
//! - `fl_x`, `fl_y` (focal lengths); when absent, `camera_angle_x` / `camera_angle_y` (full
//!   field of view in radians) give `f = 0.5·size / tan(0.5·angle)`; a missing focal along one
//!   axis copies the other (square pixels);
//! - `cx`, `cy` (default: the image centre `w/2`, `h/2`);
//! - `w`, `h` (default: read from the image file header);
//! - `k1 k2 k3 p1 p2` (default 0): OpenCV radial-tangential distortion (see
//!   [`super::distortion`]). `camera_model` other than `OPENCV`/`PINHOLE`/`SIMPLE_PINHOLE`,
//!   `is_fisheye: true`, or a non-zero `k4` (fisheye) are refused.
//!
//! Scene-level `ply_file_path` names a PLY point cloud (relative to the JSON file's folder).
//! Other keys are ignored.
//!
//! ```
//! use bbsplat::scene::nerf_json::parse_transforms;
//! use std::path::Path;
//! let json = r#"{"camera_angle_x": 0.69, "frames": [{"file_path": "./train/r_0",
//!     "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#;
//! let t = parse_transforms(json, Path::new("transforms_train.json")).unwrap();
//! assert_eq!(t.frames[0].file_path, "./train/r_0");
//! let (k, w, h) = t.frames[0].intrinsics.resolve(&t.intrinsics, 800, 800).unwrap();
//! assert!((k.fx - 0.5 * 800.0 / (0.5f64 * 0.69).tan()).abs() < 1e-9 && (w, h) == (800, 800));
//! let err = parse_transforms("{\"frames\": [", Path::new("t.json")).unwrap_err();
//! assert!(err.to_string().starts_with("t.json: malformed JSON at line 1, column 12"));
//! ```

use super::colmap::Intrinsics;
use super::distortion::Distortion;
use super::error::{Location, SceneError};
use serde_json::Value;
use std::path::Path;

/// Optional intrinsics fields of a frame or of the whole file (units: pixels, radians).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IntrinsicFields {
    /// Focal length along x.
    pub fl_x: Option<f64>,
    /// Focal length along y.
    pub fl_y: Option<f64>,
    /// Principal point x.
    pub cx: Option<f64>,
    /// Principal point y.
    pub cy: Option<f64>,
    /// Image width.
    pub w: Option<u32>,
    /// Image height.
    pub h: Option<u32>,
    /// Horizontal field of view (radians).
    pub camera_angle_x: Option<f64>,
    /// Vertical field of view (radians).
    pub camera_angle_y: Option<f64>,
    /// Radial coefficient k1.
    pub k1: Option<f64>,
    /// Radial coefficient k2.
    pub k2: Option<f64>,
    /// Radial coefficient k3.
    pub k3: Option<f64>,
    /// Tangential coefficient p1.
    pub p1: Option<f64>,
    /// Tangential coefficient p2.
    pub p2: Option<f64>,
}

/// One frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformsFrame {
    /// Image path as written in the file.
    pub file_path: String,
    /// Camera-to-world matrix rows, OpenGL camera axes (bottom row `[0, 0, 0, 1]` when only 3
    /// rows were given). The 3×3 block has been checked to be a rotation (to 1e-3) and
    /// re-orthonormalised.
    pub transform_matrix: [[f64; 4]; 4],
    /// Per-frame intrinsics (override the scene's).
    pub intrinsics: IntrinsicFields,
}

/// A parsed transforms file.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformsFile {
    /// Scene-level intrinsics.
    pub intrinsics: IntrinsicFields,
    /// `ply_file_path`, when given.
    pub ply_file_path: Option<String>,
    /// Frames in file order.
    pub frames: Vec<TransformsFrame>,
}

impl IntrinsicFields {
    /// Resolves the intrinsics of a frame (`self`) with the scene's fields as fallback, for an
    /// image whose file is `image_width × image_height`. Returns the intrinsics and the size the
    /// camera states (the image size when `w`/`h` are absent). `Err` says what is missing or
    /// invalid.
    pub fn resolve(
        &self,
        scene: &IntrinsicFields,
        image_width: u32,
        image_height: u32,
    ) -> Result<(Intrinsics, u32, u32), String> {
        let w = self.w.or(scene.w).unwrap_or(image_width);
        let h = self.h.or(scene.h).unwrap_or(image_height);
        let from_angle =
            |angle: Option<f64>, size: u32| -> Option<f64> { angle.map(|a| 0.5 * size as f64 / (0.5 * a).tan()) };
        let fx = self
            .fl_x
            .or(scene.fl_x)
            .or_else(|| from_angle(self.camera_angle_x.or(scene.camera_angle_x), w));
        let fy = self
            .fl_y
            .or(scene.fl_y)
            .or_else(|| from_angle(self.camera_angle_y.or(scene.camera_angle_y), h));
        let (fx, fy) = match (fx, fy) {
            (Some(x), Some(y)) => (x, y),
            (Some(x), None) => (x, x),
            (None, Some(y)) => (y, y),
            (None, None) => {
                return Err("no focal length: none of fl_x, fl_y, camera_angle_x, camera_angle_y is given".into());
            }
        };
        if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) {
            return Err(format!(
                "focal length ({fx}, {fy}) is not positive and finite (check camera_angle_x / fl_x)"
            ));
        }
        let get = |a: Option<f64>, b: Option<f64>| a.or(b).unwrap_or(0.0);
        let k = Intrinsics {
            fx,
            fy,
            cx: self.cx.or(scene.cx).unwrap_or(0.5 * w as f64),
            cy: self.cy.or(scene.cy).unwrap_or(0.5 * h as f64),
            distortion: Distortion {
                k1: get(self.k1, scene.k1),
                k2: get(self.k2, scene.k2),
                k3: get(self.k3, scene.k3),
                p1: get(self.p1, scene.p1),
                p2: get(self.p2, scene.p2),
            },
        };
        if let Some(problem) = k.implausibility(w, h) {
            return Err(problem);
        }
        Ok((k, w, h))
    }
}

/// Maps a serde_json syntax error to [`SceneError::Json`], with a hint for Python's `NaN` and
/// `Infinity` literals (not JSON; they mean a non-finite value was written).
fn json_error(text: &str, file: &Path, e: &serde_json::Error) -> SceneError {
    let (line, column) = (e.line(), e.column());
    let mut message = e.to_string();
    if let Some(l) = text.lines().nth(line.saturating_sub(1)) {
        let tail: String = l.chars().skip(column.saturating_sub(1)).take(10).collect();
        let tail = tail.trim_start_matches(['-', ' ']);
        if tail.starts_with("NaN") || tail.starts_with("Infinity") || tail.starts_with("inf") {
            message.push_str(" (NaN/Infinity are not valid JSON: a pose or intrinsic value is not finite)");
        }
    }
    SceneError::Json {
        file: file.to_path_buf(),
        line,
        column,
        message,
    }
}

/// Parses a transforms file. `file` is only used in error messages; errors name the JSON path
/// of the bad value (e.g. `frames[3].transform_matrix`).
///
/// A leading UTF-8 byte-order mark is ignored.
pub fn parse_transforms(text: &str, file: &Path) -> Result<TransformsFile, SceneError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let root: Value = serde_json::from_str(text).map_err(|e| json_error(text, file, &e))?;
    let err = |path: &str, m: String| SceneError::parse(file, Location::Record(path.to_string()), m);
    let Value::Object(obj) = &root else {
        return Err(err("top level", "expected a JSON object".into()));
    };
    check_model(&root, "top level").map_err(|m| err("top level", m))?;
    let intrinsics = parse_intrinsics(&root, "").map_err(|(p, m)| err(&p, m))?;
    let ply_file_path = match obj.get("ply_file_path") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(_) => return Err(err("ply_file_path", "expected a string".into())),
    };
    let frames_value = obj
        .get("frames")
        .ok_or_else(|| err("top level", "no \"frames\" array".into()))?;
    let Value::Array(frames_json) = frames_value else {
        return Err(err("frames", "expected an array".into()));
    };
    let mut frames = Vec::with_capacity(frames_json.len());
    for (i, f) in frames_json.iter().enumerate() {
        let here = format!("frames[{i}]");
        let Value::Object(fo) = f else {
            return Err(err(&here, "expected an object".into()));
        };
        let file_path = match fo.get("file_path") {
            Some(Value::String(s)) if !s.trim().is_empty() => s.clone(),
            Some(Value::String(_)) => return Err(err(&format!("{here}.file_path"), "the image path is empty".into())),
            Some(_) => return Err(err(&format!("{here}.file_path"), "expected a string".into())),
            None => return Err(err(&here, "no \"file_path\" (the image name is absent)".into())),
        };
        let here = format!("frames[{i}] ({file_path:?})");
        let matrix_path = format!("{here}.transform_matrix");
        let matrix = fo
            .get("transform_matrix")
            .ok_or_else(|| err(&here, "no \"transform_matrix\"".into()))?;
        let transform_matrix = parse_matrix(matrix).map_err(|m| err(&matrix_path, m))?;
        check_model(f, &here).map_err(|m| err(&here, m))?;
        let intrinsics = parse_intrinsics(f, &format!("{here}.")).map_err(|(p, m)| err(&p, m))?;
        frames.push(TransformsFrame {
            file_path,
            transform_matrix,
            intrinsics,
        });
    }
    Ok(TransformsFile {
        intrinsics,
        ply_file_path,
        frames,
    })
}

/// Refuses fisheye and unknown camera models.
fn check_model(v: &Value, _where: &str) -> Result<(), String> {
    if let Some(m) = v.get("camera_model") {
        match m.as_str() {
            Some("OPENCV") | Some("PINHOLE") | Some("SIMPLE_PINHOLE") | None => {}
            Some(other) => {
                return Err(format!(
                    "unsupported camera_model {other:?}; supported are OPENCV, PINHOLE and SIMPLE_PINHOLE"
                ));
            }
        }
    }
    if v.get("is_fisheye").and_then(Value::as_bool) == Some(true) {
        return Err("fisheye cameras (is_fisheye: true) are not supported".into());
    }
    if let Some(k4) = v.get("k4").and_then(Value::as_f64)
        && k4 != 0.0
    {
        return Err(format!("k4 = {k4} (a fisheye coefficient) is not supported"));
    }
    Ok(())
}

/// Reads the optional intrinsics fields of a JSON object; `prefix` is the JSON path prefix for
/// error messages. Errors are `(path, message)`.
fn parse_intrinsics(v: &Value, prefix: &str) -> Result<IntrinsicFields, (String, String)> {
    let num = |key: &str| -> Result<Option<f64>, (String, String)> {
        match v.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(x) => match x.as_f64() {
                Some(f) if f.is_finite() && (f as f32).is_finite() => Ok(Some(f)),
                Some(f) => Err((
                    format!("{prefix}{key}"),
                    format!("value {f:?} is out of range (not finite in single precision)"),
                )),
                None => Err((format!("{prefix}{key}"), format!("expected a number, found {x}"))),
            },
        }
    };
    let size = |key: &str| -> Result<Option<u32>, (String, String)> {
        match num(key)? {
            None => Ok(None),
            Some(f) if f >= 1.0 && f.fract() == 0.0 && f <= u32::MAX as f64 => Ok(Some(f as u32)),
            Some(f) => Err((
                format!("{prefix}{key}"),
                format!("image size {f} is not a positive whole number"),
            )),
        }
    };
    Ok(IntrinsicFields {
        fl_x: num("fl_x")?,
        fl_y: num("fl_y")?,
        cx: num("cx")?,
        cy: num("cy")?,
        w: size("w")?,
        h: size("h")?,
        camera_angle_x: num("camera_angle_x")?,
        camera_angle_y: num("camera_angle_y")?,
        k1: num("k1")?,
        k2: num("k2")?,
        k3: num("k3")?,
        p1: num("p1")?,
        p2: num("p2")?,
    })
}

/// Reads a 4×4 or 3×4 matrix (rows), checks it is finite and that its 3×3 block is a rotation
/// (orthonormal to 1e-3, determinant positive), and re-orthonormalises that block.
fn parse_matrix(v: &Value) -> Result<[[f64; 4]; 4], String> {
    let rows = v.as_array().ok_or("expected an array of rows")?;
    if rows.len() != 3 && rows.len() != 4 {
        return Err(format!("expected 3 or 4 rows, found {}", rows.len()));
    }
    let mut m = [[0.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]];
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array().ok_or_else(|| format!("row {r} is not an array"))?;
        if row.len() != 4 {
            return Err(format!("row {r} has {} entries, expected 4", row.len()));
        }
        for (c, x) in row.iter().enumerate() {
            let f = x
                .as_f64()
                .ok_or_else(|| format!("entry [{r}][{c}] is not a number: {x}"))?;
            if !f.is_finite() || !(f as f32).is_finite() {
                return Err(format!(
                    "entry [{r}][{c}] = {f:?} is out of range (not finite in single precision)"
                ));
            }
            m[r][c] = f;
        }
    }
    // Columns of the rotation block.
    let col = |j: usize| [m[0][j], m[1][j], m[2][j]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (a, b, c) = (col(0), col(1), col(2));
    let worst = [
        (dot(a, a) - 1.0).abs(),
        (dot(b, b) - 1.0).abs(),
        (dot(c, c) - 1.0).abs(),
        dot(a, b).abs(),
        dot(a, c).abs(),
        dot(b, c).abs(),
    ]
    .into_iter()
    .fold(0.0f64, f64::max);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    if worst > 1e-3 || dot(cross(a, b), c) <= 0.0 {
        return Err(format!(
            "the 3x3 block is not a rotation (deviation from orthonormal {worst:.2e}, determinant {:.4}): \
             scaled or mirrored camera-to-world matrices are not supported",
            dot(cross(a, b), c)
        ));
    }
    // Gram-Schmidt: a, then b orthogonalised, then c = a × b.
    let norm = |v: [f64; 3]| {
        let n = dot(v, v).sqrt();
        v.map(|x| x / n)
    };
    let a = norm(a);
    let d = dot(a, b);
    let b = norm([b[0] - d * a[0], b[1] - d * a[1], b[2] - d * a[2]]);
    let c = cross(a, b);
    for r in 0..3 {
        m[r][0] = a[r];
        m[r][1] = b[r];
        m[r][2] = c[r];
    }
    Ok(m)
}
