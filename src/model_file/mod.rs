//! Saving and loading a trained model as a folder the reference's tools can read.
//!
//! A model folder holds four files (full description, quantisation and a numpy reader in
//! `docs/model-format.md`):
//!
//! | file | content |
//! |---|---|
//! | `point_cloud.ply` | binary little-endian float32 vertices, the reference's 60 fields `x y z nx ny nz f_dc_0..2 f_rest_0..44 scale_0..1 rot_0..3` (normals 0, SH rest channel-major, log scales, raw quaternion w first; no opacity) |
//! | `texture_color.npz` | zip (deflate) with `texture_color.npy`: `uint8`, `N×3×TS×TS`, `round(255·sigmoid(logit))` |
//! | `texture_alpha.npz` | zip (deflate) with `texture_alpha.npy`: `uint8`, `N×TS×TS`, `round(255·((alpha − G) + 1)/2)`, `G` = [`alpha_asset`] |
//! | `bbsplat.json` | [`ModelMeta`] plus the format name and version; `scene`: the [`scene_mark`] of the scene trained on (optional) |
//!
//! Rounding is half to even, like `numpy.round`. Decoding (as the reference): colour `q/255`,
//! alpha `clip(2q/255 − 1 + G, 0, 1)`; texels outside [`RawBillboards::alpha_mask`] decode to 0 whatever
//! is stored. Logits are `logit(clamp(p, 1e-6, 1 − 1e-6))` ([`LOGIT_CLAMP`]); in the rare case
//! where that clamp would move a texel that decoded to exactly 0 or 1 into another quantisation
//! bin on the next save (only at exact ties), the saturating logit ±[`SATURATED_LOGIT`] (or
//! −[`ZERO_LOGIT`]) is used instead, so that saving a loaded model reproduces its files byte for
//! byte.
//!
//! [`save_model`] is atomic: it writes a temporary sibling folder, then renames it into place; an
//! existing model folder is moved aside only once the new one is complete and deleted after the
//! rename; on any error the temporary folder is removed and the old model is left (or put back)
//! in place. A `dir` that is a symbolic link is written through: the folder it names is replaced
//! and the link stays. [`load_model`] reads each file with [`file_io::read_bounded`]: a file that
//! is not a regular file (a link to `/dev/zero`, a FIFO) or is larger than
//! [`file_io::MODEL_FILE`] ([`file_io::JSON_FILE`] for `bbsplat.json`) is refused unread.
//!
//! ```
//! use bbsplat::model::RawBillboards;
//! use bbsplat::model_file::{load_model, save_model, ModelMeta};
//! use glam::Vec3;
//! let dir = std::env::temp_dir().join(format!("bbsplat-doc-{}", std::process::id()));
//! let model = RawBillboards::from_points(&[Vec3::ZERO, Vec3::X], &[[0.2, 0.4, 0.6]; 2], 16, 0);
//! let meta = ModelMeta::for_model(&model, 3, [1.0; 3]);
//! let bytes = save_model(&dir.join("model"), &model, &meta)?;
//! assert!(bytes > 2 * 240);
//! let (loaded, meta2) = load_model(&dir.join("model"))?;
//! assert_eq!(meta2, meta);
//! assert_eq!(loaded.positions, model.positions);
//! std::fs::remove_dir_all(&dir).unwrap();
//! # Ok::<(), bbsplat::model_file::ModelFileError>(())
//! ```

pub(crate) mod npz;
pub mod ply;
pub mod scene_mark;

use crate::file_io::{self, FileError};
use crate::model::{RawBillboards, alpha_asset, logit, sigmoid, standard_alpha_mask};
use crate::raster::SH_FLOATS;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use thiserror::Error;

/// Name of the geometry file.
pub const PLY_FILE: &str = "point_cloud.ply";
/// Name of the colour texture archive.
pub const COLOUR_FILE: &str = "texture_color.npz";
/// Name of the alpha texture archive.
pub const ALPHA_FILE: &str = "texture_alpha.npz";
/// Name of the metadata file.
pub const META_FILE: &str = "bbsplat.json";
/// Array name inside [`COLOUR_FILE`] (the reference's `savez_compressed(texture_color=...)`).
pub const COLOUR_ARRAY: &str = "texture_color.npy";
/// Array name inside [`ALPHA_FILE`].
pub const ALPHA_ARRAY: &str = "texture_alpha.npy";
/// Largest texture side a model folder holds (`save_model` refuses larger, `load_model` reads
/// no larger).
pub const MAX_TEXTURE_SIZE: usize = 1024;
/// Value of the `format` field of [`META_FILE`].
pub const FORMAT_NAME: &str = "bbsplat-model";
/// Version of the folder layout written (and the only one read).
pub const FORMAT_VERSION: u32 = 1;
/// Decoded probabilities are clamped to `[LOGIT_CLAMP, 1 − LOGIT_CLAMP]` before `logit`
/// (logits within ±13.8).
pub const LOGIT_CLAMP: f32 = 1e-6;
/// A logit whose f32 [`sigmoid`] is exactly 1 (used only for exact-tie bins at alpha 1).
pub const SATURATED_LOGIT: f32 = 17.0;
/// Minus this logit has an f32 [`sigmoid`] of exactly 0 (used only for exact-tie bins at 0).
pub const ZERO_LOGIT: f32 = 104.0;

/// What a model folder records besides the parameters (`bbsplat.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Texture side `TS` (16 in the reference).
    pub texture_size: usize,
    /// SH degree to render with (0-3). The PLY always stores all 16 coefficients per channel.
    pub sh_degree: u32,
    /// Background colour the model was trained against, RGB in `[0, 1]`.
    pub background: [f32; 3],
    /// Number of billboards (must equal the PLY's vertex count).
    pub billboards: usize,
    /// The scene it was trained on ([`scene_mark`]); `None` for models saved without one
    /// (absent from the file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<scene_mark::SceneMark>,
}

impl ModelMeta {
    /// The metadata of `model` with the given SH degree and background.
    pub fn for_model(model: &RawBillboards, sh_degree: u32, background: [f32; 3]) -> Self {
        ModelMeta {
            texture_size: model.texture_size,
            sh_degree,
            background,
            billboards: model.len(),
            scene: None,
        }
    }
}

/// The on-disk JSON: the meta with the format name and version first.
#[derive(Serialize, Deserialize)]
struct MetaFile {
    format: String,
    version: u32,
    #[serde(flatten)]
    meta: ModelMeta,
}

/// Errors of [`save_model`] and [`load_model`]; each names the file involved.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ModelFileError {
    /// An operating-system error on `path`.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A file of the model folder does not exist.
    #[error("{path}: missing (a model folder holds {PLY_FILE}, {COLOUR_FILE}, {ALPHA_FILE} and {META_FILE})")]
    MissingFile {
        /// The missing file.
        path: PathBuf,
    },
    /// `point_cloud.ply` is malformed: header, fields or length.
    #[error("{path}: {reason}")]
    Ply {
        /// The PLY file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A texture archive is malformed (not a zip, no such array, not uint8, truncated data).
    #[error("{path}: {reason}")]
    Npz {
        /// The npz file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A texture array has the wrong shape (count or texture size).
    #[error("{path}: array {array} has shape {found:?}, expected {expected:?}")]
    Shape {
        /// The npz file.
        path: PathBuf,
        /// The array inside.
        array: String,
        /// Shape in the file.
        found: Vec<usize>,
        /// Shape implied by the PLY vertex count and `bbsplat.json`.
        expected: Vec<usize>,
    },
    /// `bbsplat.json` and `point_cloud.ply` disagree on the number of billboards.
    #[error("{path}: says {found} billboards but {PLY_FILE} has {ply} vertices")]
    CountMismatch {
        /// The metadata file.
        path: PathBuf,
        /// Count in `bbsplat.json`.
        found: usize,
        /// Vertex count of the PLY.
        ply: usize,
    },
    /// `bbsplat.json` has another format name or version.
    #[error("{path}: format {format:?} version {version}; this build reads {FORMAT_NAME:?} version {FORMAT_VERSION}")]
    Version {
        /// The metadata file.
        path: PathBuf,
        /// The `format` field found.
        format: String,
        /// The `version` field found.
        version: u32,
    },
    /// `bbsplat.json` is not valid JSON of the expected shape, or holds impossible values.
    #[error("{path}: {reason}")]
    Meta {
        /// The metadata file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The model (or its meta) given to [`save_model`] is inconsistent; nothing was written.
    #[error("cannot save to {path}: {reason}")]
    InvalidModel {
        /// The destination folder.
        path: PathBuf,
        /// What is inconsistent.
        reason: String,
    },
    /// The destination exists and is not a model folder, so it is not replaced.
    #[error("{path} exists and is not a bbsplat model folder (no {META_FILE} or {PLY_FILE}); refusing to replace it")]
    NotAModelFolder {
        /// The destination.
        path: PathBuf,
    },
    /// A file of the folder is not a regular file (a device, a FIFO, a folder, a symlink loop)
    /// or is larger than [`file_io::MODEL_FILE`] ([`file_io::JSON_FILE`] for [`META_FILE`]): it
    /// is not read.
    #[error(transparent)]
    File(FileError),
}

/// A missing file is [`ModelFileError::MissingFile`], another operating-system error
/// [`ModelFileError::Io`], the rest [`ModelFileError::File`].
impl From<FileError> for ModelFileError {
    fn from(e: FileError) -> Self {
        match e {
            e if e.is_not_found() => ModelFileError::MissingFile {
                path: e.path().to_path_buf(),
            },
            FileError::Io { path, source, .. } => ModelFileError::Io { path, source },
            other => ModelFileError::File(other),
        }
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> ModelFileError + '_ {
    move |source| ModelFileError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Quantises an activated alpha against the asset value `g` (reference rounding, f32).
#[inline]
pub fn encode_alpha(alpha: f32, g: f32) -> u8 {
    (((alpha - g) + 1.0) * 0.5 * 255.0).round_ties_even().clamp(0.0, 255.0) as u8
}

/// Decodes a stored alpha byte: `clip(2q/255 − 1 + g, 0, 1)`.
#[inline]
pub fn decode_alpha(q: u8, g: f32) -> f32 {
    ((q as f32 / 255.0) * 2.0 - 1.0 + g).clamp(0.0, 1.0)
}

/// Quantises an activated colour: `round(255·c)`.
#[inline]
pub fn encode_colour(c: f32) -> u8 {
    (c * 255.0).round_ties_even().clamp(0.0, 255.0) as u8
}

/// Decodes a stored colour byte: `q/255`.
#[inline]
pub fn decode_colour(q: u8) -> f32 {
    q as f32 / 255.0
}

/// The logit of a decoded probability `p` whose re-encoding must give back `q`.
pub(crate) fn stable_logit(p: f32, q: u8, encode: impl Fn(f32) -> u8) -> f32 {
    let l = logit(p.clamp(LOGIT_CLAMP, 1.0 - LOGIT_CLAMP));
    if encode(sigmoid(l)) == q {
        return l;
    }
    let saturated = if p >= 0.5 { SATURATED_LOGIT } else { -ZERO_LOGIT };
    if encode(sigmoid(saturated)) == q { saturated } else { l }
}

fn check_model(dir: &Path, model: &RawBillboards, meta: &ModelMeta) -> Result<(), ModelFileError> {
    let n = model.len();
    let ts = model.texture_size;
    let t = ts * ts;
    let fail = |reason: String| {
        Err(ModelFileError::InvalidModel {
            path: dir.to_path_buf(),
            reason,
        })
    };
    if ts == 0 || ts > MAX_TEXTURE_SIZE {
        return fail(format!(
            "texture size {ts} (a model folder holds 1 to {MAX_TEXTURE_SIZE}; the loader would refuse it)"
        ));
    }
    let lengths = [
        ("quaternions", model.quaternions.len(), n),
        ("log_scales", model.log_scales.len(), n),
        ("sh", model.sh.len(), n * SH_FLOATS),
        ("alpha_logits", model.alpha_logits.len(), n * t),
        ("colour_logits", model.colour_logits.len(), n * 3 * t),
        ("alpha_mask", model.alpha_mask.len(), t),
    ];
    for (name, found, expected) in lengths {
        if found != expected {
            return fail(format!(
                "{name} has {found} values, expected {expected} for {n} billboards at TS {ts}"
            ));
        }
    }
    if model.alpha_mask != standard_alpha_mask(ts) {
        return fail(
            "the alpha mask is not the standard one (non-zero texels of the asset); the format cannot store it".into(),
        );
    }
    if meta.texture_size != ts || meta.billboards != n {
        return fail(format!(
            "meta says {} billboards at TS {}, the model has {n} at TS {ts}",
            meta.billboards, meta.texture_size
        ));
    }
    if meta.sh_degree > 3 {
        return fail(format!("SH degree {} (at most 3)", meta.sh_degree));
    }
    if let Some((billboard, field)) = first_non_finite(model) {
        return fail(format!(
            "billboard {billboard} has a non-finite {field} (NaN or infinite)"
        ));
    }
    if !meta.background.iter().all(|c| c.is_finite()) {
        return fail(format!("the background {:?} is not finite", meta.background));
    }
    Ok(())
}

/// The first billboard holding a NaN or infinite parameter, and which one.
fn first_non_finite(model: &RawBillboards) -> Option<(usize, &'static str)> {
    let t = model.texture_size * model.texture_size;
    (0..model.len()).find_map(|i| {
        let finite = |xs: &[f32]| xs.iter().all(|x| x.is_finite());
        let checks: [(&'static str, bool); 6] = [
            ("position", model.positions[i].is_finite()),
            ("rotation", finite(&model.quaternions[i])),
            ("scale", model.log_scales[i].is_finite()),
            ("SH coefficient", finite(&model.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS])),
            ("alpha texel", finite(&model.alpha_logits[i * t..(i + 1) * t])),
            ("colour texel", finite(&model.colour_logits[3 * i * t..3 * (i + 1) * t])),
        ];
        checks.into_iter().find(|(_, ok)| !ok).map(|(field, _)| (i, field))
    })
}

/// The encoded files of a model, in memory: `(name, bytes)`.
fn encode(dir: &Path, model: &RawBillboards, meta: &ModelMeta) -> Result<Vec<(&'static str, Vec<u8>)>, ModelFileError> {
    check_model(dir, model, meta)?;
    let n = model.len();
    let ts = model.texture_size;
    let t = ts * ts;
    // PLY.
    let mut ply = ply::header(n).into_bytes();
    ply.reserve(n * ply::PLY_FLOATS * 4);
    let mut row = Vec::with_capacity(ply::PLY_FLOATS);
    for i in 0..n {
        row.clear();
        row.extend_from_slice(&model.positions[i].to_array());
        row.extend_from_slice(&[0.0; 3]);
        let sh = &model.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS];
        row.extend_from_slice(&sh[..3]);
        row.extend_from_slice(&crate::stages::sh::channel_major_rest(sh));
        row.extend_from_slice(&model.log_scales[i].to_array());
        row.extend_from_slice(&model.quaternions[i]);
        debug_assert_eq!(row.len(), ply::PLY_FLOATS);
        for v in &row {
            ply.extend_from_slice(&v.to_le_bytes());
        }
    }
    // Textures.
    let g = alpha_asset(ts);
    let colour: Vec<u8> = model.colour_logits.iter().map(|&l| encode_colour(sigmoid(l))).collect();
    let alpha: Vec<u8> = model
        .alpha_logits
        .iter()
        .enumerate()
        .map(|(k, &l)| {
            let texel = k % t;
            let a = if model.alpha_mask[texel] { sigmoid(l) } else { 0.0 };
            encode_alpha(a, g[texel])
        })
        .collect();
    let zip_err = |file: &str| {
        let path = dir.join(file);
        move |e: crate::zipfile::ZipError| ModelFileError::Npz {
            path,
            reason: format!("cannot write the archive: {e}"),
        }
    };
    let colour_npz =
        npz::npz_bytes(COLOUR_ARRAY, &npz::npy_u8(&[n, 3, ts, ts], &colour)).map_err(zip_err(COLOUR_FILE))?;
    let alpha_npz = npz::npz_bytes(ALPHA_ARRAY, &npz::npy_u8(&[n, ts, ts], &alpha)).map_err(zip_err(ALPHA_FILE))?;
    let mut json = serde_json::to_vec_pretty(&MetaFile {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        meta: meta.clone(),
    })
    .expect("the meta serialises");
    json.push(b'\n');
    Ok(vec![
        (PLY_FILE, ply),
        (COLOUR_FILE, colour_npz),
        (ALPHA_FILE, alpha_npz),
        (META_FILE, json),
    ])
}

/// A fresh sibling path of `dir` with `tag` (`.name.tag-pid-counter`).
fn sibling(dir: &Path, tag: &str) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let k = COUNTER.fetch_add(1, Ordering::Relaxed);
    dir.with_file_name(format!(".{name}.{tag}-{}-{k}", std::process::id()))
}

/// Saves `model` into the folder `dir` (created, or replaced if it already holds a model) and
/// returns the total size of the files written, in bytes. See the [module
/// documentation](self) for the files and the atomic replacement.
///
/// # Errors
///
/// [`ModelFileError::InvalidModel`] (nothing written) when the model's arrays are inconsistent,
/// its alpha mask is not the standard one, or `meta` does not describe it;
/// [`ModelFileError::NotAModelFolder`] when `dir` exists but is a file or a folder that is not
/// empty and has neither `bbsplat.json` nor `point_cloud.ply`; [`ModelFileError::Io`] on
/// file-system errors (the temporary folder is removed, the previous model stays in place).
pub fn save_model(dir: &Path, model: &RawBillboards, meta: &ModelMeta) -> Result<u64, ModelFileError> {
    // Through links: a link to a model folder stays a link, the folder it names is replaced.
    let resolved = file_io::resolve_links(dir)?;
    let dir = resolved.as_path();
    if dir.file_name().is_none() {
        return Err(ModelFileError::InvalidModel {
            path: dir.to_path_buf(),
            reason: "the destination has no folder name".into(),
        });
    }
    let replacing = match fs::symlink_metadata(dir) {
        Ok(m) if m.is_dir() => {
            let is_model = dir.join(META_FILE).exists() || dir.join(PLY_FILE).exists();
            let empty = fs::read_dir(dir).map_err(io_err(dir))?.next().is_none();
            if !is_model && !empty {
                return Err(ModelFileError::NotAModelFolder {
                    path: dir.to_path_buf(),
                });
            }
            true
        }
        Ok(_) => {
            return Err(ModelFileError::NotAModelFolder {
                path: dir.to_path_buf(),
            });
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(e) => return Err(io_err(dir)(e)),
    };
    let files = encode(dir, model, meta)?;
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        fs::create_dir_all(parent).map_err(io_err(parent))?;
    }
    let tmp = sibling(dir, "tmp");
    let written = write_folder(&tmp, &files);
    let total = match written {
        Ok(total) => total,
        Err(e) => {
            let _ = fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    crate::fault::point("model", "written");
    if !replacing {
        if let Err(e) = fs::rename(&tmp, dir) {
            let _ = fs::remove_dir_all(&tmp);
            return Err(io_err(dir)(e));
        }
        crate::fault::point("model", "swapped");
    } else if exchange(&tmp, dir).is_ok() {
        // One atomic step: `dir` held the previous model until now and holds the new one from
        // now on; `tmp` holds the previous one.
        crate::fault::point("model", "swapped");
        fs::remove_dir_all(&tmp).map_err(io_err(&tmp))?;
        crate::fault::point("model", "cleaned");
    } else {
        // No atomic exchange on this system or file system: two renames, with a moment in
        // which `dir` does not exist.
        let old = sibling(dir, "old");
        if let Err(e) = fs::rename(dir, &old) {
            let _ = fs::remove_dir_all(&tmp);
            return Err(io_err(dir)(e));
        }
        if let Err(e) = fs::rename(&tmp, dir) {
            // Put the previous model back.
            let _ = fs::rename(&old, dir);
            let _ = fs::remove_dir_all(&tmp);
            return Err(io_err(dir)(e));
        }
        crate::fault::point("model", "swapped");
        fs::remove_dir_all(&old).map_err(io_err(&old))?;
        crate::fault::point("model", "cleaned");
    }
    sync_dir(dir.parent().unwrap_or(Path::new(".")));
    Ok(total)
}

/// Atomically exchanges the folders `a` and `b` (both exist): Linux `renameat2` with
/// `RENAME_EXCHANGE`. Fails where the system or the file system does not support it.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes()).map_err(std::io::Error::other);
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: both pointers are NUL-terminated paths that outlive the call; renameat2 reads
    // them and changes only the file system.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_a: &Path, _b: &Path) -> std::io::Result<()> {
    Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
}

/// Creates `tmp` and writes every file into it (each flushed to disk); returns the byte total.
fn write_folder(tmp: &Path, files: &[(&str, Vec<u8>)]) -> Result<u64, ModelFileError> {
    fs::create_dir(tmp).map_err(io_err(tmp))?;
    let mut total = 0u64;
    for (name, bytes) in files {
        let path = tmp.join(name);
        // A fresh folder: nothing is there to replace (`create_new` follows no planted link).
        let mut f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(io_err(&path))?;
        f.write_all(bytes).map_err(io_err(&path))?;
        f.sync_all().map_err(io_err(&path))?;
        total += bytes.len() as u64;
    }
    sync_dir(tmp);
    Ok(total)
}

/// Best-effort flush of a folder's entries (not supported everywhere; errors are ignored).
fn sync_dir(dir: &Path) {
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The file `path` of a model folder, of at most `limit` bytes ([`file_io::read_bounded`]).
fn read(path: &Path, limit: file_io::Limit) -> Result<Vec<u8>, ModelFileError> {
    Ok(file_io::read_bounded(path, limit)?)
}

/// Loads the model folder `dir` written by [`save_model`] (or by the reference, plus a
/// `bbsplat.json`). Textures come back as logits of the decoded values (see the [module
/// documentation](self)); geometry and SH are exact.
///
/// # Errors
///
/// [`ModelFileError::MissingFile`] for an absent file; [`ModelFileError::File`] for one that is
/// not a regular file or is too large (not read); [`ModelFileError::Meta`] /
/// [`ModelFileError::Version`] for a bad `bbsplat.json`; [`ModelFileError::Ply`] for a bad
/// header, wrong fields or a wrong length; [`ModelFileError::CountMismatch`] when the metadata
/// and the PLY disagree; [`ModelFileError::Npz`] / [`ModelFileError::Shape`] for bad texture
/// archives. Never panics on malformed files.
pub fn load_model(dir: &Path) -> Result<(RawBillboards, ModelMeta), ModelFileError> {
    let meta_path = dir.join(META_FILE);
    let meta = parse_meta(&meta_path, &read(&meta_path, file_io::JSON_FILE)?)?;
    let ply_path = dir.join(PLY_FILE);
    let rows = ply::parse(&ply_path, &read(&ply_path, file_io::MODEL_FILE)?)?;
    let n = rows.len() / ply::PLY_FLOATS;
    if let Some(k) = rows.iter().position(|x| !x.is_finite()) {
        return Err(ModelFileError::Ply {
            path: ply_path,
            reason: format!(
                "vertex {} holds a non-finite value ({}) in field {}: a model with NaN or infinite parameters is refused",
                k / ply::PLY_FLOATS,
                rows[k],
                ply::property_names()[k % ply::PLY_FLOATS]
            ),
        });
    }
    if n != meta.billboards {
        return Err(ModelFileError::CountMismatch {
            path: meta_path,
            found: meta.billboards,
            ply: n,
        });
    }
    let ts = meta.texture_size;
    let t = ts * ts;
    let colour_path = dir.join(COLOUR_FILE);
    let colour = npz::read_npz_u8(
        &colour_path,
        &read(&colour_path, file_io::MODEL_FILE)?,
        COLOUR_ARRAY,
        &[n, 3, ts, ts],
    )?;
    let alpha_path = dir.join(ALPHA_FILE);
    let alpha = npz::read_npz_u8(
        &alpha_path,
        &read(&alpha_path, file_io::MODEL_FILE)?,
        ALPHA_ARRAY,
        &[n, ts, ts],
    )?;

    let mut model = RawBillboards {
        positions: Vec::with_capacity(n),
        quaternions: Vec::with_capacity(n),
        log_scales: Vec::with_capacity(n),
        sh: vec![0.0; n * SH_FLOATS],
        alpha_logits: crate::memory::with_capacity(n * t),
        colour_logits: crate::memory::with_capacity(n * 3 * t),
        alpha_mask: standard_alpha_mask(ts),
        texture_size: ts,
    };
    for (i, r) in rows.chunks_exact(ply::PLY_FLOATS).enumerate() {
        model.positions.push(Vec3::new(r[0], r[1], r[2]));
        let sh = &mut model.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS];
        sh[..3].copy_from_slice(&r[6..9]);
        for c in 0..3 {
            for k in 1..16 {
                sh[3 * k + c] = r[9 + c * 15 + (k - 1)];
            }
        }
        model.log_scales.push(Vec2::new(r[54], r[55]));
        model.quaternions.push([r[56], r[57], r[58], r[59]]);
    }
    model
        .colour_logits
        .extend(colour.iter().map(|&q| stable_logit(decode_colour(q), q, encode_colour)));
    let g = alpha_asset(ts);
    model.alpha_logits.extend(alpha.iter().enumerate().map(|(k, &q)| {
        let texel = k % t;
        if model.alpha_mask[texel] {
            let gt = g[texel];
            stable_logit(decode_alpha(q, gt), q, |a| encode_alpha(a, gt))
        } else {
            // Held at alpha 0 by the mask; the logit is never read (from_points also stores 0).
            0.0
        }
    }));
    Ok((model, meta))
}

fn parse_meta(path: &Path, bytes: &[u8]) -> Result<ModelMeta, ModelFileError> {
    let bad = |reason: String| ModelFileError::Meta {
        path: path.to_path_buf(),
        reason,
    };
    let value: serde_json::Value =
        serde_json::from_slice(file_io::without_bom(bytes)).map_err(|e| bad(format!("not valid JSON: {e}")))?;
    let format = value.get("format").and_then(|v| v.as_str()).unwrap_or("").to_string();
    let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
    if format != FORMAT_NAME || version != FORMAT_VERSION as u64 {
        return Err(ModelFileError::Version {
            path: path.to_path_buf(),
            format,
            version: version.min(u32::MAX as u64) as u32,
        });
    }
    let file: MetaFile = serde_json::from_value(value).map_err(|e| bad(format!("bad field: {e}")))?;
    let meta = file.meta;
    if meta.texture_size == 0 || meta.texture_size > MAX_TEXTURE_SIZE {
        return Err(bad(format!(
            "texture_size {} (expected 1 to {MAX_TEXTURE_SIZE})",
            meta.texture_size
        )));
    }
    if meta.sh_degree > 3 {
        return Err(bad(format!("sh_degree {} (at most 3)", meta.sh_degree)));
    }
    if !meta.background.iter().all(|c| c.is_finite()) {
        return Err(bad(format!("background {:?} is not finite", meta.background)));
    }
    Ok(meta)
}
