//! Training checkpoints: everything needed to continue a run bit for bit.
//!
//! # Format (version 5)
//!
//! Little-endian, no padding. `T = TS²`, `n` = number of billboards.
//!
//! | field | type | notes |
//! |---|---|---|
//! | magic | 8 bytes | `BBSPLCKP` |
//! | version | u32 | 6 (versions 1 to 5 are still read, see [`OLDEST_VERSION`]) |
//! | file length | u64 | total bytes including the checksum |
//! | iterations | u64 | [`TrainConfig::iterations`] |
//! | sh_degree | u32 | ≤ 3 |
//! | background | 3 × f32 | |
//! | seed | u64 | |
//! | extent | f32 | |
//! | impact_threshold, texture_reg_weight, opacity_reg_weight | 3 × f32 | |
//! | adam mode | u8 | 0 dense, 1 sparse, 2 lazy |
//! | texture mode | u8 | 0 full, 1 Gaussian |
//! | relocate | u8 | 0 / 1 |
//! | relocate_every | u64 | |
//! | learning-rate multipliers | 4 × f32 | [`super::LearningRateScales`] in field order; absent in version 1 (read as all 1) |
//! | clamp gradient | u8 | [`super::ClampGradient`]: 0 exact, 1 pass-through (straight-through); absent in versions 1-2 (read as exact, what they trained with) |
//! | geometry regularisers | 4 × f32 | [`super::geometry::GeometryRegularisers`]: `lambda_normal`, `lambda_distortion`, `normal_from`, `distortion_from`; absent in versions 1-4 (read as off, the default) |
//! | error growth | f32 | [`TrainConfig::error_growth`], in `[0, 1]`; absent in versions 1-5 (read as 0: growth by copies alone, what they grew with) |
//! | step | u64 | steps done |
//! | RNG state | 4 × u64 | [`crate::rng::Rng::state`] |
//! | order length `k`, order | u64, `k` × u64 | view indices still on the shuffled stack (popped from the end) |
//! | n, TS | u64, u64 | TS ≥ 2 |
//! | alpha mask | `T` × u8 | 0 / 1 |
//! | positions, quaternions, log-scales | `3n`, `4n`, `2n` × f32 | |
//! | SH | `48n` × f32 | `[billboard][coeff][rgb]` |
//! | alpha logits, colour logits | `Tn`, `3Tn` × f32 | exact bits (masked texels included) |
//! | opacity count `o`, opacity logits | u64 (0 or n), `o` × f32 | Gaussian mode |
//! | group count | u32 | 8, order of [`super::group`] |
//! | per group: row_len, rows, global step | 3 × u64 | rows = n |
//! | per group: m, v | 2 × `rows·row_len` × f32 | |
//! | per group: update counts | `rows` × u32 | lazy mode: the live step each texture and SH-rest row is up to date through |
//! | lazy logs (lazy mode only) | 3 × (u64 `k`, `k` × 2 f32: step size, √(1−β₂ᵗ)) | [`super::lazy_adam::LazyLog`] of the alpha, colour and SH-rest groups |
//! | **growth and time budget** (version 4; absent before: no growth, no budget) | | |
//! | growth cap | u64 | [`TrainConfig::growth_cap`] |
//! | learning rate by run length | u8 | [`TrainConfig::lr_by_run_length`], 0 / 1 |
//! | time plan present | u8 | 0 / 1; then, when 1, the [`TimePlan`] fields: |
//! | budget, spent | 2 × f64 | seconds |
//! | coarse step estimate, coarse steps measured | f64, u64 | |
//! | fine step estimate, fine steps measured | f64, u64 | |
//! | fine from | u64 | the step full resolution started at; `u64::MAX`: not yet |
//! | calibration steps, calibrated ratio | u64, f64 | |
//! | **run record** (version 4) | | |
//! | record length `r` | u64 | |
//! | record | `r` bytes | UTF-8 JSON of [`RunRecord`]: the run's arguments and the dataset fingerprint; absent in versions 1-3 (read as empty) |
//! | checksum | u64 | FNV-1a 64 of every preceding byte |
//!
//! Derived state is not stored: the activated textures (recomputed from the logits), the
//! regulariser's `A0` and the Gaussian shape (from TS and the mask), and the gradient buffers
//! (always zero between steps).
//!
//! Reading checks, in order: magic, version, stored length against the file's length
//! (shorter: [`CheckpointError::Truncated`]), checksum, then every count against what the config
//! and the model imply ([`CheckpointError::Inconsistent`]). It never panics on bad input and never
//! allocates more than the file's size.

use super::adam::{AdamGroup, StepFactors};
use super::geometry::GeometryRegularisers;
use super::lazy_adam::LazyLog;
use super::run_record::RunRecord;
use super::time_budget::TimePlan;
use super::{AdamMode, ClampGradient, LearningRateScales, TextureMode, TrainConfig, Trainer, adam_groups, group};
use crate::file_io::FileError;
use crate::model::RawBillboards;
use crate::raster::SH_FLOATS;
use crate::rng::Rng;
use glam::{Vec2, Vec3};
use std::io::Write;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// File magic.
pub const MAGIC: [u8; 8] = *b"BBSPLCKP";
/// Format version written (and the newest read).
pub const VERSION: u32 = 6;

/// Oldest format version still read. Version 1 lacks the learning-rate multipliers, read as
/// [`super::LearningRateScales::REFERENCE`]; versions 1 and 2 lack the clamp gradient, read as
/// [`ClampGradient::Exact`] (the only one the trainer used before it became a setting); versions
/// 1 to 3 lack the growth and time-budget section, read as no growth and no budget, and the run
/// record, read as empty ([`RunRecord::default`]); versions 1 to 4 lack the geometry
/// regularisers, read as off ([`super::geometry::GeometryRegularisers::default`]); versions 1 to 5
/// lack the error-growth share, read as 0 (growth by copies alone).
pub const OLDEST_VERSION: u32 = 1;

/// What went wrong reading or writing a checkpoint; every variant names the file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CheckpointError {
    /// The file system refused.
    #[error("checkpoint {path}: {action}: {source}")]
    Io {
        /// The checkpoint path.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Not a bbsplat checkpoint.
    #[error("checkpoint {path}: not a bbsplat checkpoint (bad magic bytes)")]
    BadMagic {
        /// The checkpoint path.
        path: PathBuf,
    },
    /// Written by another format version.
    #[error("checkpoint {path}: format version {found} is not supported (this build reads versions {oldest} to {supported})", oldest = OLDEST_VERSION)]
    UnsupportedVersion {
        /// The checkpoint path.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// Newest version this build reads.
        supported: u32,
    },
    /// The file ends before its stated length.
    #[error("checkpoint {path}: truncated: {found} bytes, {expected} expected ({what})")]
    Truncated {
        /// The checkpoint path.
        path: PathBuf,
        /// Bytes expected.
        expected: u64,
        /// Bytes found.
        found: u64,
        /// Where it ended.
        what: String,
    },
    /// The content does not match its checksum (corrupted).
    #[error("checkpoint {path}: corrupted: checksum {computed:#018x} does not match the stored {stored:#018x}")]
    Checksum {
        /// The checkpoint path.
        path: PathBuf,
        /// Stored checksum.
        stored: u64,
        /// Checksum of the content.
        computed: u64,
    },
    /// Sizes or values that contradict each other.
    #[error("checkpoint {path}: inconsistent: {what}")]
    Inconsistent {
        /// The checkpoint path.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The file is not one to read or write: not a regular file (a device, a FIFO, a folder, a
    /// symlink loop), or larger than [`crate::file_io::CHECKPOINT`].
    #[error(transparent)]
    File(FileError),
}

/// An operating-system error stays [`CheckpointError::Io`]; the rest is [`CheckpointError::File`].
impl From<FileError> for CheckpointError {
    fn from(e: FileError) -> Self {
        match e {
            FileError::Io { path, action, source } => CheckpointError::Io { path, action, source },
            other => CheckpointError::File(other),
        }
    }
}

/// Where [`encode_into`] puts the checkpoint bytes: counted, or hashed and written.
trait Sink {
    fn put(&mut self, bytes: &[u8]);
}

impl<S: Sink> Sink for &mut S {
    fn put(&mut self, bytes: &[u8]) {
        (**self).put(bytes);
    }
}

/// Counts the bytes (first pass of a streamed save: the header stores the file length).
struct Counter(u64);

impl Sink for Counter {
    fn put(&mut self, bytes: &[u8]) {
        self.0 += bytes.len() as u64;
    }
}

/// Writes through to `out` while hashing; the first I/O error is kept and later writes skipped.
struct HashingWriter<W: Write> {
    out: W,
    hash: u64,
    error: Option<std::io::Error>,
}

impl<W: Write> Sink for HashingWriter<W> {
    fn put(&mut self, bytes: &[u8]) {
        if self.error.is_some() {
            return;
        }
        self.hash = crate::fnv::update(self.hash, bytes);
        if let Err(e) = self.out.write_all(bytes) {
            self.error = Some(e);
        }
    }
}

struct Writer<S: Sink>(S);

impl<S: Sink> Writer<S> {
    fn u8(&mut self, x: u8) {
        self.0.put(&[x]);
    }
    fn u32(&mut self, x: u32) {
        self.0.put(&x.to_le_bytes());
    }
    fn u64(&mut self, x: u64) {
        self.0.put(&x.to_le_bytes());
    }
    fn f32(&mut self, x: f32) {
        self.0.put(&x.to_le_bytes());
    }
    fn f64(&mut self, x: f64) {
        self.0.put(&x.to_le_bytes());
    }
    /// Little-endian floats, converted through a small buffer so that large arrays stream
    /// without a second copy of their size.
    fn f32s(&mut self, xs: &[f32]) {
        let mut buf = [0u8; 4 * 1024];
        for chunk in xs.chunks(1024) {
            for (b, x) in buf.chunks_exact_mut(4).zip(chunk) {
                b.copy_from_slice(&x.to_le_bytes());
            }
            self.0.put(&buf[..4 * chunk.len()]);
        }
    }
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn inconsistent(&self, what: impl Into<String>) -> CheckpointError {
        CheckpointError::Inconsistent {
            path: self.path.to_path_buf(),
            what: what.into(),
        }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], CheckpointError> {
        if self.data.len() - self.pos < n {
            return Err(self.inconsistent(format!(
                "{what} needs {n} bytes at offset {} but only {} remain",
                self.pos,
                self.data.len() - self.pos
            )));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8, CheckpointError> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, CheckpointError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64, CheckpointError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    fn f32(&mut self, what: &str) -> Result<f32, CheckpointError> {
        Ok(f32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn f64(&mut self, what: &str) -> Result<f64, CheckpointError> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    /// A count stored as u64 that must fit the remaining bytes at `unit` bytes each.
    fn count(&mut self, unit: usize, what: &str) -> Result<usize, CheckpointError> {
        let c = self.u64(what)?;
        let remaining = (self.data.len() - self.pos) as u64;
        if c.checked_mul(unit.max(1) as u64).is_none_or(|b| b > remaining) {
            return Err(self.inconsistent(format!("{what} = {c} does not fit the {remaining} remaining bytes")));
        }
        Ok(c as usize)
    }
    fn f32s(&mut self, n: usize, what: &str) -> Result<Vec<f32>, CheckpointError> {
        let bytes = n
            .checked_mul(4)
            .ok_or_else(|| self.inconsistent(format!("{what}: size overflows")))?;
        let raw = self.take(bytes, what)?;
        // Texture and moment arrays are the large ones: keep them on huge pages (crate::memory).
        let mut out = crate::memory::with_capacity(n);
        out.extend(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))),
        );
        Ok(out)
    }
    fn flag(&mut self, what: &str) -> Result<bool, CheckpointError> {
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            x => Err(self.inconsistent(format!("{what} = {x}, expected 0 or 1"))),
        }
    }
}

/// The checkpoint of `tr` in memory.
fn encode(tr: &Trainer) -> Vec<u8> {
    let len = encoded_len(tr);
    write_checkpoint(tr, len, Vec::with_capacity(len as usize)).expect("writing to a Vec cannot fail")
}

/// Writes the whole checkpoint of `tr` (total length `len`, from [`encoded_len`]) to `out`,
/// hashing the bytes on the way and appending the checksum; returns `out`, not flushed.
fn write_checkpoint<W: Write>(tr: &Trainer, len: u64, out: W) -> std::io::Result<W> {
    let mut sink = HashingWriter {
        out,
        hash: crate::fnv::BASIS,
        error: None,
    };
    encode_into(tr, len, &mut sink);
    if let Some(e) = sink.error {
        return Err(e);
    }
    let mut out = sink.out;
    out.write_all(&sink.hash.to_le_bytes())?;
    Ok(out)
}

/// Total checkpoint length in bytes, checksum included (a counting pass of [`encode_into`]).
fn encoded_len(tr: &Trainer) -> u64 {
    let mut counter = Counter(0);
    encode_into(tr, 0, &mut counter);
    counter.0 + 8
}

/// Every byte of the checkpoint before the checksum; `len` is the total file length stored in
/// the header.
fn encode_into<S: Sink>(tr: &Trainer, len: u64, sink: &mut S) {
    let mut w = Writer(sink);
    w.0.put(&MAGIC);
    w.u32(VERSION);
    w.u64(len);
    let c = &tr.config;
    w.u64(c.iterations as u64);
    w.u32(c.sh_degree);
    w.f32s(&c.background.to_array());
    w.u64(c.seed);
    w.f32(c.extent);
    w.f32(c.impact_threshold);
    w.f32(c.texture_reg_weight);
    w.f32(c.opacity_reg_weight);
    w.u8(match c.adam {
        AdamMode::Dense => 0,
        AdamMode::Sparse => 1,
        AdamMode::Lazy => 2,
    });
    w.u8(match c.texture_mode {
        TextureMode::Full => 0,
        TextureMode::Gaussian => 1,
    });
    w.u8(c.relocate as u8);
    w.u64(c.relocate_every as u64);
    w.f32s(&c.lr_scales.to_array());
    w.u8(match c.clamp_gradient {
        ClampGradient::Exact => 0,
        ClampGradient::PassThrough => 1,
    });
    let g = &c.geometry;
    w.f32s(&[g.lambda_normal, g.lambda_distortion, g.normal_from, g.distortion_from]);
    w.f32(c.error_growth);
    w.u64(tr.step as u64);
    for s in tr.rng.state() {
        w.u64(s);
    }
    w.u64(tr.order.len() as u64);
    for &o in &tr.order {
        w.u64(o as u64);
    }
    let m = &tr.model;
    w.u64(m.len() as u64);
    w.u64(m.texture_size as u64);
    for &b in &m.alpha_mask {
        w.u8(b as u8);
    }
    for p in &m.positions {
        w.f32s(&p.to_array());
    }
    for q in &m.quaternions {
        w.f32s(q);
    }
    for s in &m.log_scales {
        w.f32s(&s.to_array());
    }
    w.f32s(&m.sh);
    w.f32s(&m.alpha_logits);
    w.f32s(&m.colour_logits);
    w.u64(tr.opacity_logits.len() as u64);
    w.f32s(&tr.opacity_logits);
    w.u32(tr.adam.len() as u32);
    for g in &tr.adam {
        w.u64(g.row_len as u64);
        w.u64(g.rows() as u64);
        w.u64(g.global_step);
        w.f32s(&g.m);
        w.f32s(&g.v);
        for &s in &g.steps {
            w.u32(s);
        }
    }
    if tr.config.adam == AdamMode::Lazy {
        for log in &tr.lazy_logs {
            w.u64(log.factors.len() as u64);
            for f in &log.factors {
                w.f32s(&[f.step_size(), f.bc2_sqrt()]);
            }
        }
    }
    encode_growth_and_plan(tr, &mut w);
    // Run record (version 4).
    let record = serde_json::to_vec(&tr.record).expect("the run record serialises");
    w.u64(record.len() as u64);
    w.0.put(&record);
}

/// The version-4 section: growth cap and time plan.
fn encode_growth_and_plan<S: Sink>(tr: &Trainer, w: &mut Writer<S>) {
    w.u64(tr.config.growth_cap as u64);
    w.u8(tr.config.lr_by_run_length as u8);
    match &tr.time_plan {
        None => w.u8(0),
        Some(p) => {
            w.u8(1);
            w.f64(p.budget_seconds);
            w.f64(p.spent_seconds);
            w.f64(p.coarse_step_seconds);
            w.u64(p.coarse_steps);
            w.f64(p.fine_step_seconds);
            w.u64(p.fine_steps);
            w.u64(p.fine_from.map_or(u64::MAX, |s| s as u64));
            w.u64(p.calibration_steps);
            w.f64(p.calibrated_ratio);
        }
    }
}

/// Reads the version-4 section: `(growth cap, learning rate by run length, time plan)`.
fn decode_growth_and_plan(r: &mut Reader<'_>) -> Result<(usize, bool, Option<TimePlan>), CheckpointError> {
    let cap = r.u64("growth cap")?;
    let cap = usize::try_from(cap).map_err(|_| r.inconsistent(format!("growth cap {cap} does not fit")))?;
    let by_length = r.flag("learning rate by run length")?;
    if !r.flag("time plan present")? {
        return Ok((cap, by_length, None));
    }
    let what = "time plan";
    let plan = TimePlan {
        budget_seconds: r.f64(what)?,
        spent_seconds: r.f64(what)?,
        coarse_step_seconds: r.f64(what)?,
        coarse_steps: r.u64(what)?,
        fine_step_seconds: r.f64(what)?,
        fine_steps: r.u64(what)?,
        fine_from: match r.u64(what)? {
            u64::MAX => None,
            s => Some(s as usize),
        },
        calibration_steps: r.u64(what)?,
        calibrated_ratio: r.f64(what)?,
    };
    let times = [
        plan.budget_seconds,
        plan.spent_seconds,
        plan.coarse_step_seconds,
        plan.fine_step_seconds,
        plan.calibrated_ratio,
    ];
    if !times.iter().all(|x| x.is_finite() && *x >= 0.0) {
        return Err(r.inconsistent(format!("time plan {plan:?} holds negative or non-finite seconds")));
    }
    Ok((cap, by_length, Some(plan)))
}

/// Reads a checkpoint, section by section in the order of the format table (module docs).
fn decode(data: &[u8], path: &Path) -> Result<Trainer, CheckpointError> {
    let (version, body) = check_envelope(data, path)?;
    let mut r = Reader {
        data: body,
        pos: 20,
        path,
    };
    let mut config = decode_config(&mut r, version)?;
    let step = r.u64("step")? as usize;
    let rng = Rng::from_state([r.u64("RNG")?, r.u64("RNG")?, r.u64("RNG")?, r.u64("RNG")?]);
    let k = r.count(8, "view-order length")?;
    let order = (0..k)
        .map(|_| r.u64("view order").map(|x| x as usize))
        .collect::<Result<Vec<_>, _>>()?;
    let model = decode_model(&mut r)?;
    let n = model.len();
    let t = model.texture_size * model.texture_size;
    let opacity_logits = decode_opacity_logits(&mut r, config.texture_mode, n)?;
    let adam = decode_adam(&mut r, n, t)?;
    let mut lazy_logs: [LazyLog; 3] = Default::default();
    if config.adam == AdamMode::Lazy {
        for log in &mut lazy_logs {
            let k = r.count(8, "lazy Adam log length")?;
            let values = r.f32s(2 * k, "lazy Adam log")?;
            log.factors = values
                .chunks_exact(2)
                .map(|f| StepFactors::from_parts(f[0], f[1]))
                .collect();
        }
    }
    let (growth_cap, lr_by_run_length, time_plan) = if version >= 4 {
        decode_growth_and_plan(&mut r)?
    } else {
        (0, false, None)
    };
    config.growth_cap = growth_cap;
    config.lr_by_run_length = lr_by_run_length;
    let record = decode_record(&mut r, version)?;
    if r.pos != body.len() {
        return Err(r.inconsistent(format!("{} unexpected bytes before the checksum", body.len() - r.pos)));
    }
    let mut trainer = Trainer::with_adam(
        model,
        TrainConfig {
            texture_mode: TextureMode::Full,
            ..config
        },
        adam,
    );
    trainer.config = config;
    trainer.opacity_logits = opacity_logits;
    if config.texture_mode == TextureMode::Gaussian {
        for b in 0..n {
            trainer.refresh_row(b);
        }
    }
    trainer.lazy_logs = lazy_logs;
    trainer.order = order;
    trainer.rng = rng;
    trainer.step = step;
    trainer.record = record;
    trainer.time_plan = time_plan;
    Ok(trainer)
}

/// The checks of the whole file before any field is read: magic, version, stated length
/// against the file's, checksum. Returns the version and the body (the bytes before the
/// checksum; the fields start at offset 20).
fn check_envelope<'d>(data: &'d [u8], path: &Path) -> Result<(u32, &'d [u8]), CheckpointError> {
    let p = || path.to_path_buf();
    if data.len() < 8 || data[..8] != MAGIC {
        return Err(CheckpointError::BadMagic { path: p() });
    }
    if data.len() < 20 {
        return Err(CheckpointError::Truncated {
            path: p(),
            expected: 20,
            found: data.len() as u64,
            what: "inside the header".into(),
        });
    }
    let version = u32::from_le_bytes(data[8..12].try_into().expect("4 bytes"));
    if !(OLDEST_VERSION..=VERSION).contains(&version) {
        return Err(CheckpointError::UnsupportedVersion {
            path: p(),
            found: version,
            supported: VERSION,
        });
    }
    let stated = u64::from_le_bytes(data[12..20].try_into().expect("8 bytes"));
    let found = data.len() as u64;
    if found < stated {
        return Err(CheckpointError::Truncated {
            path: p(),
            expected: stated,
            found,
            what: "the file is shorter than its header states".into(),
        });
    }
    if found > stated || stated < 28 {
        return Err(CheckpointError::Inconsistent {
            path: p(),
            what: format!("the header states {stated} bytes but the file has {found}"),
        });
    }
    let (body, tail) = data.split_at(data.len() - 8);
    let stored = u64::from_le_bytes(tail.try_into().expect("8 bytes"));
    let computed = crate::fnv::fnv1a(body);
    if stored != computed {
        return Err(CheckpointError::Checksum {
            path: p(),
            stored,
            computed,
        });
    }
    Ok((version, body))
}

/// The training settings, from `iterations` to the error-growth share (fields a `version`
/// lacks read as what it trained with); the growth cap and the learning rate by run length,
/// stored later, are left 0 and false.
fn decode_config(r: &mut Reader<'_>, version: u32) -> Result<TrainConfig, CheckpointError> {
    let iterations = r.u64("iterations")? as usize;
    let sh_degree = r.u32("sh_degree")?;
    if sh_degree > 3 {
        return Err(r.inconsistent(format!("SH degree {sh_degree} > 3")));
    }
    let background = Vec3::new(r.f32("background")?, r.f32("background")?, r.f32("background")?);
    let seed = r.u64("seed")?;
    let extent = r.f32("extent")?;
    let impact_threshold = r.f32("impact_threshold")?;
    let texture_reg_weight = r.f32("texture_reg_weight")?;
    let opacity_reg_weight = r.f32("opacity_reg_weight")?;
    let adam = match r.u8("adam mode")? {
        0 => AdamMode::Dense,
        1 => AdamMode::Sparse,
        2 => AdamMode::Lazy,
        x => return Err(r.inconsistent(format!("unknown Adam mode {x}"))),
    };
    let texture_mode = match r.u8("texture mode")? {
        0 => TextureMode::Full,
        1 => TextureMode::Gaussian,
        x => return Err(r.inconsistent(format!("unknown texture mode {x}"))),
    };
    let relocate = r.flag("relocate")?;
    let relocate_every = r.u64("relocate_every")? as usize;
    let lr_scales = if version >= 2 {
        let what = "learning-rate multipliers";
        let scales = LearningRateScales {
            position: r.f32(what)?,
            sh: r.f32(what)?,
            shape: r.f32(what)?,
            texture: r.f32(what)?,
        };
        if !scales.to_array().iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(r.inconsistent(format!("learning-rate multipliers {scales:?} are not finite and ≥ 0")));
        }
        scales
    } else {
        LearningRateScales::REFERENCE
    };
    let clamp_gradient = if version >= 3 {
        match r.u8("clamp gradient")? {
            0 => ClampGradient::Exact,
            1 => ClampGradient::PassThrough,
            x => return Err(r.inconsistent(format!("unknown clamp gradient {x}"))),
        }
    } else {
        ClampGradient::Exact
    };
    let geometry = if version >= 5 {
        let what = "geometry regularisers";
        let g = GeometryRegularisers {
            lambda_normal: r.f32(what)?,
            lambda_distortion: r.f32(what)?,
            normal_from: r.f32(what)?,
            distortion_from: r.f32(what)?,
        };
        if let Some(problem) = g.problem() {
            return Err(r.inconsistent(problem));
        }
        g
    } else {
        GeometryRegularisers::default()
    };
    let error_growth = if version >= 6 {
        let share = r.f32("error growth share")?;
        if !(0.0..=1.0).contains(&share) {
            return Err(r.inconsistent(format!("error growth share {share} is not between 0 and 1")));
        }
        share
    } else {
        0.0
    };
    Ok(TrainConfig {
        iterations,
        sh_degree,
        background,
        seed,
        extent,
        impact_threshold,
        texture_reg_weight,
        opacity_reg_weight,
        adam,
        texture_mode,
        relocate,
        relocate_every,
        growth_cap: 0,
        error_growth,
        lr_by_run_length: false,
        lr_scales,
        clamp_gradient,
        geometry,
        // A speed choice of the machine, not of the run: not saved.
        simd: crate::cpu::Simd::detect(),
    })
}

/// The raw parameters: count, texture size, alpha mask, then the arrays.
fn decode_model(r: &mut Reader<'_>) -> Result<RawBillboards, CheckpointError> {
    let n = r.count(4 * SH_FLOATS, "billboard count")?;
    let ts = r.u64("texture size")?;
    if !(2..=4096).contains(&ts) {
        return Err(r.inconsistent(format!("texture size {ts} outside 2..=4096")));
    }
    let ts = ts as usize;
    let t = ts * ts;
    let alpha_mask = (0..t).map(|_| r.flag("alpha mask")).collect::<Result<Vec<_>, _>>()?;
    let positions = r.f32s(3 * n, "positions")?;
    let quaternions = r.f32s(4 * n, "quaternions")?;
    let log_scales = r.f32s(2 * n, "log-scales")?;
    let sh = r.f32s(SH_FLOATS * n, "SH")?;
    let alpha_logits = r.f32s(t * n, "alpha logits")?;
    let colour_logits = r.f32s(3 * t * n, "colour logits")?;
    Ok(RawBillboards {
        positions: positions.chunks_exact(3).map(Vec3::from_slice).collect(),
        quaternions: quaternions.chunks_exact(4).map(|q| [q[0], q[1], q[2], q[3]]).collect(),
        log_scales: log_scales.chunks_exact(2).map(Vec2::from_slice).collect(),
        sh,
        alpha_logits,
        colour_logits,
        alpha_mask,
        texture_size: ts,
    })
}

/// The Gaussian-mode opacity logits: `n` of them in that mode, none in full-texture mode.
fn decode_opacity_logits(r: &mut Reader<'_>, texture_mode: TextureMode, n: usize) -> Result<Vec<f32>, CheckpointError> {
    let o = r.count(4, "opacity count")?;
    let expected_o = if texture_mode == TextureMode::Gaussian { n } else { 0 };
    if o != expected_o {
        return Err(r.inconsistent(format!(
            "{o} opacity logits for {n} billboards in {texture_mode:?} mode (expected {expected_o})"
        )));
    }
    r.f32s(o, "opacity logits")
}

/// The Adam groups, in the order of [`group`], each with `n` rows (texture groups: `t` texels a
/// row).
fn decode_adam(r: &mut Reader<'_>, n: usize, t: usize) -> Result<[AdamGroup; group::COUNT], CheckpointError> {
    let groups = r.u32("group count")? as usize;
    if groups != group::COUNT {
        return Err(r.inconsistent(format!("{groups} Adam groups, expected {}", group::COUNT)));
    }
    let mut adam = adam_groups(0, t);
    for (gi, g) in adam.iter_mut().enumerate() {
        let row_len = r.u64("Adam row length")? as usize;
        let expected_len = g.row_len;
        if row_len != expected_len {
            return Err(r.inconsistent(format!(
                "Adam group {gi}: row length {row_len}, expected {expected_len}"
            )));
        }
        let rows = r.u64("Adam rows")? as usize;
        if rows != n {
            return Err(r.inconsistent(format!("Adam group {gi}: {rows} rows for {n} billboards")));
        }
        let global_step = r.u64("Adam global step")?;
        let m = r.f32s(rows * row_len, "Adam first moments")?;
        let v = r.f32s(rows * row_len, "Adam second moments")?;
        let steps = (0..rows)
            .map(|_| r.u32("Adam update counts"))
            .collect::<Result<Vec<_>, _>>()?;
        *g = AdamGroup {
            row_len,
            m,
            v,
            steps,
            global_step,
        };
    }
    Ok(adam)
}

/// The run record (version 4; empty before).
fn decode_record(r: &mut Reader<'_>, version: u32) -> Result<RunRecord, CheckpointError> {
    if version < 4 {
        return Ok(RunRecord::default());
    }
    let len = r.count(1, "run record length")?;
    let bytes = r.take(len, "run record")?;
    serde_json::from_slice::<RunRecord>(bytes).map_err(|e| r.inconsistent(format!("the run record is not valid: {e}")))
}

/// Writes `bytes` to `path` atomically ([`crate::file_io::write_atomic`]: a temporary file in
/// the same folder, flushed to disk, then renamed over `path`, through links; a device, a FIFO
/// or a folder at `path` is refused). On error the temporary file is removed and `path` is
/// untouched. Each stage is a fault point (`<file name>:<stage>`, module `fault`).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CheckpointError> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// Like [`write_atomic`], the content written by `write` into the temporary file (which it must
/// not leave partly buffered: flush any buffer it wraps around the file).
fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<(), CheckpointError> {
    let name = path.file_name().unwrap_or_default().to_string_lossy().into_owned();
    crate::file_io::write_atomic_staged(path, write, |stage| crate::fault::point(&name, stage)).map_err(Into::into)
}

impl Trainer {
    /// The checkpoint bytes of the current state (format in the [module docs](self)).
    pub fn checkpoint_bytes(&self) -> Vec<u8> {
        encode(self)
    }

    /// Rebuilds a trainer from checkpoint bytes; `path` only names the source in errors.
    ///
    /// # Errors
    /// See [`CheckpointError`].
    pub fn from_checkpoint_bytes(bytes: &[u8], path: &Path) -> Result<Trainer, CheckpointError> {
        decode(bytes, path)
    }

    /// Saves the whole training state to `path` atomically (temporary file + rename).
    ///
    /// The file is streamed (a counting pass gives the length stored in the header, then the
    /// bytes go through a 1 MiB buffer while being hashed), so saving needs no in-memory copy of
    /// the checkpoint; the bytes are those of [`Trainer::checkpoint_bytes`].
    ///
    /// # Errors
    /// [`CheckpointError::Io`] when the folder cannot be written; [`CheckpointError::File`] when
    /// `path` (links followed) is a folder, a device or a FIFO (left as it is).
    pub fn save_checkpoint(&self, path: impl AsRef<Path>) -> Result<(), CheckpointError> {
        let len = encoded_len(self);
        write_atomic_with(path.as_ref(), |file| {
            write_checkpoint(self, len, std::io::BufWriter::with_capacity(1 << 20, file))?.flush()
        })
    }

    /// Loads a trainer saved by [`Trainer::save_checkpoint`]; continuing it is bit-identical to
    /// continuing the trainer that was saved.
    ///
    /// # Errors
    /// See [`CheckpointError`]: unreadable file, not a regular file or larger than
    /// [`crate::file_io::CHECKPOINT`] (refused before reading), bad magic, unsupported version,
    /// truncated, corrupted (checksum) or inconsistent sizes.
    pub fn load_checkpoint(path: impl AsRef<Path>) -> Result<Trainer, CheckpointError> {
        let path = path.as_ref();
        let bytes = crate::file_io::read_bounded(path, crate::file_io::CHECKPOINT)?;
        decode(&bytes, path)
    }
}
