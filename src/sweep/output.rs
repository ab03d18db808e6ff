//! Sweep outputs: CSV, JSON, markdown table and SVG plots, each written atomically.

use super::{SweepError, SweepRecord, pareto_front, plot_curves_svg, plot_psnr_vs_size_svg, plot_psnr_vs_time_svg};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Paths of the files written by [`write_outputs`].
#[derive(Clone, Debug, PartialEq)]
pub struct SweepFiles {
    /// `sweep.csv`: one row per run.
    pub csv: PathBuf,
    /// `sweep.json`: every record with its slug and Pareto flags.
    pub json: PathBuf,
    /// `sweep.md`: the markdown table.
    pub markdown: PathBuf,
    /// `psnr_vs_time.svg`.
    pub psnr_vs_time: PathBuf,
    /// `psnr_vs_size.svg`.
    pub psnr_vs_size: PathBuf,
    /// `curves.svg`.
    pub curves: PathBuf,
}

/// Writes `bytes` to `path` through a temporary file beside it and a rename, so readers never
/// see a partial file ([`crate::file_io::write_atomic`]: through links; a device, a FIFO or a
/// folder at `path` is refused). Errors name the file that failed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    Ok(crate::file_io::write_atomic(path, bytes)?)
}

/// Model size in bytes as a Pareto cost; 0 (the trainer saved no model) is unknown (NaN), so
/// such a run is never on the size front.
pub(crate) fn size_cost(bytes: u64) -> f64 {
    if bytes == 0 { f64::NAN } else { bytes as f64 }
}

/// Pareto flags per record: (PSNR vs training time, PSNR vs model size).
pub(crate) fn fronts(records: &[SweepRecord]) -> (Vec<bool>, Vec<bool>) {
    let flags = |points: Vec<(f64, f64)>| {
        let mut on = vec![false; points.len()];
        for i in pareto_front(&points) {
            on[i] = true;
        }
        on
    };
    (
        flags(
            records
                .iter()
                .map(|r| (r.summary.train_seconds, r.summary.test_psnr))
                .collect(),
        ),
        flags(
            records
                .iter()
                .map(|r| (size_cost(r.summary.model_bytes), r.summary.test_psnr))
                .collect(),
        ),
    )
}

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

/// Header of [`csv_table`].
pub const CSV_HEADER: &str = "slug,iterations,billboards,alive,texture_size,sh_degree,width,height,max_width,\
texture_threshold,texture_mode,seed,threads,train_seconds,render_ms_per_frame,test_psnr,test_ssim,test_views,\
model_bytes,peak_rss_bytes,pareto_time,pareto_size,test_lpips,lpips_network";

/// The records as CSV with header [`CSV_HEADER`]: one row per record, in order. Iterations,
/// billboards, texture size and seed are the values the run reports; `max_width`,
/// `texture_threshold` and `texture_mode` are the requested flags (empty: trainer default).
/// Units: seconds, milliseconds, bytes, dB. The Pareto columns are `1` or `0`. `test_lpips` and
/// `lpips_network` are empty for a run without LPIPS (a sweep computes it when its runs are given
/// `--lpips`: `-- --lpips` after the sweep's own flags).
pub fn csv_table(records: &[SweepRecord]) -> String {
    let (time, size) = fronts(records);
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for (i, r) in records.iter().enumerate() {
        let (s, m) = (&r.setting, &r.summary);
        let fields = [
            s.slug(),
            m.iterations.to_string(),
            m.billboards.to_string(),
            m.alive.to_string(),
            m.texture_size.to_string(),
            m.sh_degree.to_string(),
            m.resolution[0].to_string(),
            m.resolution[1].to_string(),
            opt(s.max_width),
            opt(s.texture_threshold),
            opt(s.texture_mode),
            m.seed.to_string(),
            m.threads.to_string(),
            m.train_seconds.to_string(),
            m.render_ms_per_frame.to_string(),
            m.test_psnr.to_string(),
            m.test_ssim.to_string(),
            m.test_views.to_string(),
            m.model_bytes.to_string(),
            m.peak_rss_bytes.to_string(),
            u8::from(time[i]).to_string(),
            u8::from(size[i]).to_string(),
            opt(m.test_lpips),
            opt(m.lpips_network.as_deref()),
        ];
        let quoted: Vec<String> = fields.iter().map(|f| csv_field(f)).collect();
        out.push_str(&quoted.join(","));
        out.push('\n');
    }
    out
}

/// Bytes as MB (10⁶) with `decimals`, or `n/a` for 0 (unknown).
fn mb(bytes: u64, decimals: usize) -> String {
    if bytes == 0 {
        "n/a".into()
    } else {
        format!("{:.*}", decimals, bytes as f64 / 1e6)
    }
}

pub(crate) fn csv_field(f: &str) -> String {
    if f.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", f.replace('"', "\"\""))
    } else {
        f.to_string()
    }
}

/// The records as a markdown table, in order: budget, measured speed and quality, and a Pareto
/// column naming the fronts the run is on (`time`: PSNR vs training time, `size`: PSNR vs model
/// size). Model size and peak RSS in MB (10⁶ bytes); `n/a` where the summary has 0 (no model saved,
/// or no peak-RSS reading on the platform), and such a run is on no size front. LPIPS with its
/// network (`0.1234 vgg`), `-` for a run without it.
///
/// ```
/// use bbsplat::sweep::markdown_table;
/// let table = markdown_table(&[]);
/// assert!(table.starts_with("| run |"));
/// assert_eq!(table.lines().count(), 2);
/// ```
pub fn markdown_table(records: &[SweepRecord]) -> String {
    let (time, size) = fronts(records);
    let mut out = String::from(
        "| run | iterations | billboards | alive | TS | mode | σ | resolution | train s | render ms | \
         PSNR dB | SSIM | LPIPS | model MB | peak RSS MB | Pareto |\n\
         |---|--:|--:|--:|--:|---|--:|---|--:|--:|--:|--:|--:|--:|--:|---|\n",
    );
    for (i, r) in records.iter().enumerate() {
        let (s, m) = (&r.setting, &r.summary);
        let pareto = match (time[i], size[i]) {
            (true, true) => "time, size",
            (true, false) => "time",
            (false, true) => "size",
            (false, false) => "",
        };
        let or_default = |v: String| if v.is_empty() { "default".to_string() } else { v };
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {} | {}×{} | {:.1} | {:.2} | {:.2} | {:.4} | {} | {} | {} | {} |",
            s.slug(),
            m.iterations,
            m.billboards,
            m.alive,
            m.texture_size,
            or_default(opt(s.texture_mode)),
            or_default(opt(s.texture_threshold)),
            m.resolution[0],
            m.resolution[1],
            m.train_seconds,
            m.render_ms_per_frame,
            m.test_psnr,
            m.test_ssim,
            m.test_lpips.map_or("-".into(), |d| format!(
                "{d:.4} {}",
                m.lpips_network.as_deref().unwrap_or("?")
            )),
            mb(m.model_bytes, 2),
            mb(m.peak_rss_bytes, 0),
            pareto
        );
    }
    out
}

#[derive(Serialize)]
struct JsonRecord<'a> {
    slug: String,
    pareto_time: bool,
    pareto_size: bool,
    #[serde(flatten)]
    record: &'a SweepRecord,
}

#[derive(Serialize)]
struct JsonFile<'a> {
    version: u32,
    records: Vec<JsonRecord<'a>>,
}

/// Writes `sweep.csv`, `sweep.json`, `sweep.md`, `psnr_vs_time.svg`, `psnr_vs_size.svg` and
/// `curves.svg` into `dir` (created if needed), each atomically.
///
/// `sweep.json` is `{"version": 1, "records": [{"slug", "pareto_time", "pareto_size",
/// "setting": Setting, "summary": TrainSummary}, ...]}`; NaN values are written as `null`.
pub fn write_outputs(dir: &Path, records: &[SweepRecord]) -> Result<SweepFiles, SweepError> {
    std::fs::create_dir_all(dir).map_err(|source| SweepError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let files = SweepFiles {
        csv: dir.join("sweep.csv"),
        json: dir.join("sweep.json"),
        markdown: dir.join("sweep.md"),
        psnr_vs_time: dir.join("psnr_vs_time.svg"),
        psnr_vs_size: dir.join("psnr_vs_size.svg"),
        curves: dir.join("curves.svg"),
    };
    write_atomic(&files.csv, csv_table(records).as_bytes())?;
    let (time, size) = fronts(records);
    let json = JsonFile {
        version: 1,
        records: records
            .iter()
            .enumerate()
            .map(|(i, record)| JsonRecord {
                slug: record.setting.slug(),
                pareto_time: time[i],
                pareto_size: size[i],
                record,
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&json).map_err(|source| SweepError::Json {
        path: files.json.clone(),
        source,
    })?;
    write_atomic(&files.json, text.as_bytes())?;
    write_atomic(&files.markdown, markdown_table(records).as_bytes())?;
    let with_path = |path: &Path, r: Result<String, SweepError>| {
        r.map_err(|e| match e {
            SweepError::Plot { message, .. } => SweepError::Plot {
                path: path.to_path_buf(),
                message,
            },
            other => other,
        })
    };
    write_atomic(
        &files.psnr_vs_time,
        with_path(&files.psnr_vs_time, plot_psnr_vs_time_svg(records))?.as_bytes(),
    )?;
    write_atomic(
        &files.psnr_vs_size,
        with_path(&files.psnr_vs_size, plot_psnr_vs_size_svg(records))?.as_bytes(),
    )?;
    write_atomic(
        &files.curves,
        with_path(&files.curves, plot_curves_svg(records))?.as_bytes(),
    )?;
    Ok(files)
}
