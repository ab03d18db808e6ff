//! COLMAP binary sparse models (`cameras.bin`, `images.bin`, `points3D.bin`): parsers taking
//! bytes and writers returning bytes.
//!
//! Layout (little-endian throughout, as written by COLMAP's `WriteBinaryLittleEndian`):
//! - `cameras.bin`: `u64 count`, then per camera `u32 camera_id, i32 model_id, u64 width,
//!   u64 height, num_params(model) × f64`.
//! - `images.bin`: `u64 count`, then per image `u32 image_id, 4 × f64 qvec (w, x, y, z),
//!   3 × f64 tvec, u32 camera_id, name bytes, 0u8, u64 num_points2D,
//!   num_points2D × (f64 x, f64 y, i64 point3D_id)` (`-1`, i.e. `u64::MAX`, means none).
//! - `points3D.bin`: `u64 count`, then per point `u64 point3D_id, 3 × f64 xyz, 3 × u8 rgb,
//!   f64 error, u64 track_length, track_length × (u32 image_id, u32 point2D_idx)`.
//!
//! The parsers never panic and never allocate more than the file can hold: a count larger than
//! the remaining bytes allow is refused before reading. Trailing bytes after the last record are
//! an error (they mean the counts and the data disagree).
//!
//! ```
//! use bbsplat::scene::colmap::{CameraModel, ColmapCamera};
//! use bbsplat::scene::colmap_binary::{parse_cameras, write_cameras};
//! use std::path::Path;
//! let cams = vec![ColmapCamera { id: 3, model: CameraModel::Pinhole, width: 64, height: 48,
//!     params: vec![50.0, 51.0, 32.0, 24.0] }];
//! let bytes = write_cameras(&cams);
//! assert_eq!(parse_cameras(&bytes, Path::new("cameras.bin")).unwrap(), cams);
//! let err = parse_cameras(&bytes[..60], Path::new("cameras.bin")).unwrap_err();
//! assert_eq!(err.to_string(), "cameras.bin: camera 0 (camera_id 3), byte offset 56: \
//!     file ends while reading parameter 3: 8 bytes needed, 4 left (the file is 60 bytes long)");
//! ```

use super::colmap::{CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint3D, IdSet, Point2D, TrackElement};
use super::error::{Location, SceneError};
use std::path::Path;

/// A little-endian reader over a file's bytes that knows which record it is in.
struct Reader<'a> {
    file: &'a Path,
    bytes: &'a [u8],
    pos: usize,
    record: String,
}

impl<'a> Reader<'a> {
    fn new(file: &'a Path, bytes: &'a [u8]) -> Self {
        Reader {
            file,
            bytes,
            pos: 0,
            record: "header".into(),
        }
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn err_at(&self, offset: usize, message: impl Into<String>) -> SceneError {
        SceneError::parse(
            self.file,
            Location::Binary {
                record: self.record.clone(),
                offset: offset as u64,
            },
            message,
        )
    }

    fn err(&self, message: impl Into<String>) -> SceneError {
        self.err_at(self.pos, message)
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], SceneError> {
        let end = self.pos.checked_add(N).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let mut out = [0u8; N];
                out.copy_from_slice(&self.bytes[self.pos..end]);
                self.pos = end;
                Ok(out)
            }
            None => Err(self.err(format!(
                "file ends while reading {what}: {N} bytes needed, {} left (the file is {} bytes long)",
                self.remaining(),
                self.bytes.len()
            ))),
        }
    }

    fn u8(&mut self, what: &str) -> Result<u8, SceneError> {
        Ok(self.take::<1>(what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, SceneError> {
        Ok(u32::from_le_bytes(self.take(what)?))
    }
    fn i32(&mut self, what: &str) -> Result<i32, SceneError> {
        Ok(i32::from_le_bytes(self.take(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64, SceneError> {
        Ok(u64::from_le_bytes(self.take(what)?))
    }
    fn i64(&mut self, what: &str) -> Result<i64, SceneError> {
        Ok(i64::from_le_bytes(self.take(what)?))
    }
    fn f64(&mut self, what: &str) -> Result<f64, SceneError> {
        Ok(f64::from_le_bytes(self.take(what)?))
    }

    /// Reads a count of items of at least `min_size` bytes each and checks that the rest of
    /// the file can hold them. Returns the count as `usize`.
    fn count(&mut self, what: &str, min_size: usize) -> Result<usize, SceneError> {
        let at = self.pos;
        let n = self.u64(&format!("the number of {what}"))?;
        let fits = (n as u128) * (min_size as u128) <= self.remaining() as u128;
        if !fits {
            return Err(self.err_at(
                at,
                format!(
                    "the file says {n} {what} follow, but only {} bytes remain (each takes at least {min_size} bytes): \
                     the count is corrupt or the file is truncated",
                    self.remaining()
                ),
            ));
        }
        // `n · min_size ≤ remaining ≤ usize::MAX`, so the conversion cannot fail when
        // `min_size ≥ 1`; all callers pass a positive size.
        usize::try_from(n).map_err(|_| self.err_at(at, format!("{n} {what} is too many")))
    }

    fn finish(mut self) -> Result<(), SceneError> {
        if self.remaining() != 0 {
            self.record = "end of file".into();
            return Err(self.err(format!(
                "{} unexpected bytes after the last record (the record count and the data disagree)",
                self.remaining()
            )));
        }
        Ok(())
    }
}

/// Parses `cameras.bin`. `file` is only used in error messages.
pub fn parse_cameras(bytes: &[u8], file: &Path) -> Result<Vec<ColmapCamera>, SceneError> {
    let mut r = Reader::new(file, bytes);
    let n = r.count("cameras", 24)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = IdSet::new();
    for i in 0..n {
        r.record = format!("camera {i}");
        let start = r.pos;
        let id = r.u32("camera_id")?;
        r.record = format!("camera {i} (camera_id {id})");
        let model_at = r.pos;
        let model_id = r.i32("model_id")?;
        let model = CameraModel::from_id(model_id).map_err(|model| SceneError::UnsupportedCameraModel {
            file: file.to_path_buf(),
            location: Location::Binary {
                record: r.record.clone(),
                offset: model_at as u64,
            },
            model,
        })?;
        let width = r.u64("width")?;
        let height = r.u64("height")?;
        let mut params = Vec::with_capacity(model.num_params());
        for k in 0..model.num_params() {
            params.push(r.f64(&format!("parameter {k}"))?);
        }
        let cam = ColmapCamera {
            id,
            model,
            width,
            height,
            params,
        };
        cam.check()
            .and_then(|()| ids.insert("camera_id", id))
            .map_err(|m| r.err_at(start, m))?;
        out.push(cam);
    }
    r.finish()?;
    Ok(out)
}

/// Parses `images.bin`. `file` is only used in error messages.
pub fn parse_images(bytes: &[u8], file: &Path) -> Result<Vec<ColmapImage>, SceneError> {
    let mut r = Reader::new(file, bytes);
    let n = r.count("images", 64 + 1 + 8)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = IdSet::new();
    for i in 0..n {
        r.record = format!("image {i}");
        let start = r.pos;
        let id = r.u32("image_id")?;
        r.record = format!("image {i} (image_id {id})");
        let mut qvec = [0.0; 4];
        for (k, q) in qvec.iter_mut().enumerate() {
            *q = r.f64(&format!("qvec[{k}]"))?;
        }
        let mut tvec = [0.0; 3];
        for (k, t) in tvec.iter_mut().enumerate() {
            *t = r.f64(&format!("tvec[{k}]"))?;
        }
        let camera_id = r.u32("camera_id")?;
        let name_at = r.pos;
        let name_len = r.bytes[r.pos..]
            .iter()
            .position(|&b| b == 0)
            .ok_or_else(|| r.err("file ends while reading the image name (no terminating NUL byte)"))?;
        let name_bytes = &r.bytes[r.pos..r.pos + name_len];
        let name = std::str::from_utf8(name_bytes)
            .map_err(|e| {
                r.err_at(
                    name_at,
                    format!(
                        "image name is not valid UTF-8 (invalid byte at position {} of the name {:?})",
                        e.valid_up_to(),
                        String::from_utf8_lossy(name_bytes)
                    ),
                )
            })?
            .to_string();
        r.pos += name_len + 1;
        r.record = format!("image {i} (image_id {id}, {name:?})");
        let m = r.count("2D points", 24)?;
        let mut points2d = Vec::with_capacity(m);
        for _ in 0..m {
            let x = r.f64("a 2D point")?;
            let y = r.f64("a 2D point")?;
            let point3d_id = r.i64("a 2D point")?;
            points2d.push(Point2D { xy: [x, y], point3d_id });
        }
        let image = ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        };
        image
            .check()
            .and_then(|()| ids.insert("image_id", id))
            .map_err(|m| r.err_at(start, m))?;
        out.push(image);
    }
    r.finish()?;
    Ok(out)
}

/// Parses `points3D.bin`. `file` is only used in error messages.
pub fn parse_points(bytes: &[u8], file: &Path) -> Result<Vec<ColmapPoint3D>, SceneError> {
    let mut r = Reader::new(file, bytes);
    let n = r.count("points", 43 + 8)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = IdSet::new();
    for i in 0..n {
        r.record = format!("point {i}");
        let start = r.pos;
        let id = r.u64("point3D_id")?;
        r.record = format!("point {i} (point3D_id {id})");
        let mut xyz = [0.0; 3];
        for (k, v) in xyz.iter_mut().enumerate() {
            *v = r.f64(&format!("xyz[{k}]"))?;
        }
        let rgb = [r.u8("red")?, r.u8("green")?, r.u8("blue")?];
        let error = r.f64("error")?;
        let m = r.count("track elements", 8)?;
        let mut track = Vec::with_capacity(m);
        for _ in 0..m {
            let image_id = r.u32("a track element")?;
            let point2d_idx = r.u32("a track element")?;
            track.push(TrackElement { image_id, point2d_idx });
        }
        if xyz.iter().any(|v| !v.is_finite()) {
            return Err(r.err_at(start, format!("position {xyz:?} is not finite")));
        }
        ids.insert("point3D_id", id).map_err(|m| r.err_at(start, m))?;
        out.push(ColmapPoint3D {
            id,
            xyz,
            rgb,
            error,
            track,
        });
    }
    r.finish()?;
    Ok(out)
}

/// Serialises cameras in the `cameras.bin` layout.
pub fn write_cameras(cameras: &[ColmapCamera]) -> Vec<u8> {
    let mut out = Vec::with_capacity(8 + cameras.len() * 56);
    out.extend((cameras.len() as u64).to_le_bytes());
    for c in cameras {
        out.extend(c.id.to_le_bytes());
        out.extend(c.model.id().to_le_bytes());
        out.extend(c.width.to_le_bytes());
        out.extend(c.height.to_le_bytes());
        for p in &c.params {
            out.extend(p.to_le_bytes());
        }
    }
    out
}

/// Serialises images in the `images.bin` layout. Names must not contain NUL bytes (the reader
/// refuses such names anyway).
pub fn write_images(images: &[ColmapImage]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend((images.len() as u64).to_le_bytes());
    for im in images {
        out.extend(im.id.to_le_bytes());
        for q in im.qvec {
            out.extend(q.to_le_bytes());
        }
        for t in im.tvec {
            out.extend(t.to_le_bytes());
        }
        out.extend(im.camera_id.to_le_bytes());
        out.extend(im.name.as_bytes());
        out.push(0);
        out.extend((im.points2d.len() as u64).to_le_bytes());
        for p in &im.points2d {
            out.extend(p.xy[0].to_le_bytes());
            out.extend(p.xy[1].to_le_bytes());
            out.extend(p.point3d_id.to_le_bytes());
        }
    }
    out
}

/// Serialises 3D points in the `points3D.bin` layout.
pub fn write_points(points: &[ColmapPoint3D]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend((points.len() as u64).to_le_bytes());
    for p in points {
        out.extend(p.id.to_le_bytes());
        for v in p.xyz {
            out.extend(v.to_le_bytes());
        }
        out.extend(p.rgb);
        out.extend(p.error.to_le_bytes());
        out.extend((p.track.len() as u64).to_le_bytes());
        for t in &p.track {
            out.extend(t.image_id.to_le_bytes());
            out.extend(t.point2d_idx.to_le_bytes());
        }
    }
    out
}

/// Writes `cameras.bin`, `images.bin` and `points3D.bin` into `dir` (which must exist).
pub fn write_model(model: &ColmapModel, dir: &Path) -> Result<(), SceneError> {
    let files = [
        ("cameras.bin", write_cameras(&model.cameras)),
        ("images.bin", write_images(&model.images)),
        ("points3D.bin", write_points(&model.points)),
    ];
    for (name, bytes) in files {
        let path = dir.join(name);
        crate::file_io::write_atomic(&path, &bytes)?;
    }
    Ok(())
}
