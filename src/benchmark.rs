//! The table of `bbsplat benchmark`: one row per scene read back from its run's `summary.json`,
//! the paper's published BBSplat row beside it where the scene is one of the paper's, written as
//! markdown and JSON.
//!
//! Units: PSNR in dB and SSIM on 8-bit images (as [`crate::report`]), LPIPS as
//! [`crate::lpips`] (lower is better), time in wall-clock seconds of training steps, memory in
//! bytes (the markdown shows MB = 10⁶ bytes). The paper's figures are its own runs at full
//! resolution with 30k steps on a GPU; ours are the runs of the table (downscaled data, a time
//! budget, a CPU), so the two columns are side by side, not like for like.

use crate::file_io::{self, FileError};
use crate::report::SummaryFile;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Where [`PAPER_ROWS`] come from.
pub const PAPER_SOURCE: &str = "BBSplat paper supplement, Table 9, column \"BBSplat (Ours)\" (PSNR / SSIM / LPIPS)";

/// A scene's published BBSplat figures.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PaperRow {
    /// The dataset of Table 9: `Tanks&Temples`, `Mip-NeRF-360` or `DTU`.
    pub dataset: &'static str,
    /// The scene as Table 9 names it (`Scan65`, `Truck`, ...).
    pub scene: &'static str,
    /// PSNR, dB.
    pub psnr: f64,
    /// SSIM.
    pub ssim: f64,
    /// LPIPS (VGG, as the reference evaluates).
    pub lpips: f64,
}

const fn row(dataset: &'static str, scene: &'static str, psnr: f64, ssim: f64, lpips: f64) -> PaperRow {
    PaperRow {
        dataset,
        scene,
        psnr,
        ssim,
        lpips,
    }
}

const TNT: &str = "Tanks&Temples";
const M360: &str = "Mip-NeRF-360";
const DTU: &str = "DTU";

/// Every row of the BBSplat column of Table 9 ([`PAPER_SOURCE`]), in its order. NeRF-synthetic
/// (lego), LLFF (fern) and the project's own captures (beer_colmap, fox) are not in it.
pub const PAPER_ROWS: [PaperRow; 27] = [
    row(TNT, "Train", 21.38, 0.7702, 0.2604),
    row(TNT, "Truck", 24.19, 0.8418, 0.1957),
    row(TNT, "Francis", 28.56, 0.9079, 0.2334),
    row(TNT, "Horse", 24.72, 0.8847, 0.1604),
    row(TNT, "Lighthouse", 22.75, 0.8332, 0.2214),
    row(M360, "Room", 31.13, 0.9146, 0.2150),
    row(M360, "Kitchen", 30.35, 0.9116, 0.1430),
    row(M360, "Bonsai", 29.62, 0.9085, 0.2334),
    row(M360, "Counter", 28.30, 0.8941, 0.2061),
    row(M360, "Bicycle", 23.28, 0.6520, 0.3096),
    row(M360, "Garden", 25.75, 0.7873, 0.1907),
    row(M360, "Stump", 24.00, 0.6547, 0.3376),
    row(DTU, "Scan24", 27.47, 0.8850, 0.1677),
    row(DTU, "Scan37", 24.93, 0.8670, 0.2127),
    row(DTU, "Scan40", 25.56, 0.8709, 0.2081),
    row(DTU, "Scan55", 27.74, 0.8511, 0.2746),
    row(DTU, "Scan63", 30.32, 0.9422, 0.1652),
    row(DTU, "Scan65", 29.67, 0.8754, 0.2803),
    row(DTU, "Scan69", 26.71, 0.8660, 0.2845),
    row(DTU, "Scan83", 28.97, 0.8685, 0.3604),
    row(DTU, "Scan97", 27.39, 0.8579, 0.3268),
    row(DTU, "Scan105", 29.35, 0.8765, 0.3154),
    row(DTU, "Scan106", 32.93, 0.9020, 0.3133),
    row(DTU, "Scan110", 31.42, 0.8798, 0.3324),
    row(DTU, "Scan114", 29.72, 0.8870, 0.2976),
    row(DTU, "Scan118", 34.41, 0.9090, 0.3077),
    row(DTU, "Scan122", 34.41, 0.9069, 0.3092),
];

/// Lower-case letters and digits of `s` only.
fn letters_and_digits(s: &str) -> String {
    s.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// The paper's row of a scene named as its folder (`dtu_scan65`, `scan65`, `DTU-Scan65`,
/// `truck`, `m360_kitchen`): the name's letters and digits, less case, equal to the paper's
/// scene name or to its dataset's name (`dtu`, `tnt`, `tanksandtemples`, `mipnerf360`, `m360`)
/// followed by it.
///
/// ```
/// use bbsplat::benchmark::paper_row;
/// assert_eq!(paper_row("dtu_scan65").unwrap().psnr, 29.67);
/// assert!(paper_row("scan6").is_none() && paper_row("lego").is_none());
/// ```
pub fn paper_row(name: &str) -> Option<&'static PaperRow> {
    let name = letters_and_digits(name);
    let prefixes: &[&str] = &["", "dtu", "tnt", "tanksandtemples", "mipnerf360", "m360"];
    PAPER_ROWS.iter().find(|r| {
        let scene = letters_and_digits(r.scene);
        prefixes
            .iter()
            .any(|p| name.strip_prefix(p).is_some_and(|rest| rest == scene))
    })
}

/// Errors reading a run back.
#[derive(Debug, thiserror::Error)]
pub enum BenchmarkError {
    /// The summary could not be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// The summary is not a `bbsplat train` summary.
    #[error("{path}: not a bbsplat train summary: {message}")]
    Summary {
        /// The file.
        path: PathBuf,
        /// What the JSON reader said.
        message: String,
    },
}

/// How long each scene of a benchmark trains: `bbsplat train --minutes M` (the paper's way
/// of comparing at equal time) or `--iterations N` (equal steps; a run of a step count is the same
/// model on any machine and thread count).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BenchmarkBudget {
    /// A time budget in minutes (`--minutes`).
    Minutes(f64),
    /// A step count (`--iterations`).
    Steps(usize),
}

impl BenchmarkBudget {
    /// The `bbsplat train` flag and value of this budget.
    pub fn train_flag(&self) -> [String; 2] {
        match self {
            Self::Minutes(m) => ["--minutes".into(), m.to_string()],
            Self::Steps(n) => ["--iterations".into(), n.to_string()],
        }
    }

    /// "30 minutes" or "7000 steps".
    pub fn describe(&self) -> String {
        match self {
            Self::Minutes(m) => format!("{m} minutes"),
            Self::Steps(n) => format!("{n} steps"),
        }
    }

    /// Whether `row` (a finished run) is a run of this budget.
    pub fn holds(&self, row: &BenchmarkRow) -> bool {
        match (*self, row.budget_minutes) {
            (Self::Minutes(m), Some(b)) => (b - m).abs() <= 1e-9 * m.max(1.0),
            (Self::Steps(n), None) => row.iterations == Some(n),
            _ => false,
        }
    }

    /// The run a finished `row` holds, in the words of [`BenchmarkBudget::describe`] ("a
    /// --minutes 5 run", "a 300-step run").
    pub fn of_row(row: &BenchmarkRow) -> String {
        match (row.budget_minutes, row.iterations) {
            (Some(b), _) => format!("a --minutes {b} run"),
            (None, Some(n)) => format!("a {n}-step run"),
            (None, None) => "a run of unknown length".into(),
        }
    }
}

/// What one scene's run gave (all `None` but the names and `error` when it failed).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchmarkRow {
    /// The row's name: the scene folder's last component, also the run's folder under the
    /// benchmark's output.
    pub name: String,
    /// The scene folder as given.
    pub scene: String,
    /// Why the scene has no figures (the error of its run); `None` when it ran.
    pub error: Option<String>,
    /// The run's time budget (`--minutes`), from its plan; `None` for a run of a step count.
    pub budget_minutes: Option<f64>,
    /// Mean test PSNR, dB.
    pub psnr: Option<f64>,
    /// Mean test SSIM.
    pub ssim: Option<f64>,
    /// Mean test LPIPS and its network (`vgg`, `alex`), when the run computed it.
    pub lpips: Option<(String, f64)>,
    /// Mean PSNR and SSIM over the test views' mask pixels, when the scene has masks.
    pub masked: Option<(f64, f64)>,
    /// Test views scored.
    pub test_views: Option<usize>,
    /// Seconds spent in training steps.
    pub train_seconds: Option<f64>,
    /// Steps run.
    pub iterations: Option<usize>,
    /// Billboards at the end.
    pub billboards: Option<usize>,
    /// Peak resident memory of the run's process, bytes (0 where the platform does not say).
    pub peak_rss_bytes: Option<u64>,
    /// `(minutes, test PSNR)` of each evaluation during training.
    pub curve: Vec<(f64, f64)>,
    /// The paper's row, when the scene is in Table 9 ([`paper_row`]).
    pub paper: Option<PaperRow>,
}

impl BenchmarkRow {
    /// A row without figures: the scene's run failed with `error`.
    pub fn failed(name: &str, scene: &str, error: String) -> Self {
        Self {
            name: name.into(),
            scene: scene.into(),
            error: Some(error),
            budget_minutes: None,
            psnr: None,
            ssim: None,
            lpips: None,
            masked: None,
            test_views: None,
            train_seconds: None,
            iterations: None,
            billboards: None,
            peak_rss_bytes: None,
            curve: Vec::new(),
            paper: paper_row(name).copied(),
        }
    }

    /// The row of a finished run, read from its `summary.json` at `path`.
    pub fn from_summary(name: &str, scene: &str, path: &Path) -> Result<Self, BenchmarkError> {
        let text = file_io::read_text_bounded(path, file_io::JSON_FILE)?;
        let invalid = |e: serde_json::Error| BenchmarkError::Summary {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let value: serde_json::Value = serde_json::from_str(&text).map_err(invalid)?;
        let file: SummaryFile = serde_json::from_value(value.clone()).map_err(invalid)?;
        let s = file.summary;
        let masked = value
            .get("masked_test")
            .and_then(|m| Some((m.get("psnr")?.as_f64()?, m.get("ssim")?.as_f64()?)));
        let finite = |v: f64| v.is_finite().then_some(v);
        Ok(Self {
            name: name.into(),
            scene: scene.into(),
            error: None,
            budget_minutes: file.record.plan.map(|p| p.budget_minutes),
            psnr: finite(s.test_psnr),
            ssim: finite(s.test_ssim),
            lpips: s.lpips_network.zip(s.test_lpips),
            masked,
            test_views: Some(s.test_views),
            train_seconds: Some(s.train_seconds),
            iterations: Some(s.iterations),
            billboards: Some(s.billboards),
            peak_rss_bytes: Some(s.peak_rss_bytes),
            curve: s.curve.iter().map(|c| (c.seconds / 60.0, c.psnr)).collect(),
            paper: paper_row(name).copied(),
        })
    }
}

fn cell(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.decimals$}"))
}

/// The markdown table of `rows` (a run of `budget` each, `bbsplat train` given `extra_flags`
/// besides, e.g. `--lpips=vgg`): ours and the paper's figures side by side, then the failed
/// scenes with their errors.
///
/// ```
/// use bbsplat::benchmark::{BenchmarkBudget, BenchmarkRow, markdown_table};
/// let row = BenchmarkRow::failed("dtu_scan65", "data/dtu_scan65", "no such folder".into());
/// let md = markdown_table(&[row], BenchmarkBudget::Minutes(30.0), &["--lpips=vgg".into()]);
/// assert!(md.contains("| dtu_scan65 |") && md.contains("29.67") && md.contains("no such folder"));
/// assert!(md.contains("`bbsplat train SCENE --minutes 30 --lpips=vgg` with no other flag"));
/// ```
pub fn markdown_table(rows: &[BenchmarkRow], budget: BenchmarkBudget, extra_flags: &[String]) -> String {
    let command: Vec<String> = budget
        .train_flag()
        .into_iter()
        .chain(extra_flags.iter().cloned())
        .collect();
    let command = command.join(" ");
    let mut out = format!(
        "Each scene trained by `bbsplat train SCENE {command}` with no other flag; test \
         views as the scene's protocol (its test split, else every 8th view). Paper: {PAPER_SOURCE}; \
         \"not in Table 9\" where the scene is not one of its scenes.\n\n\
         | scene | PSNR (dB) | SSIM | LPIPS | masked PSNR / SSIM | test views | train time (s) | steps | billboards | peak memory (MB) | paper PSNR / SSIM / LPIPS |\n\
         |---|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|\n"
    );
    for r in rows {
        let paper = r.paper.map_or("not in Table 9".into(), |p| {
            format!(
                "{:.2} / {:.4} / {:.4} ({} {})",
                p.psnr, p.ssim, p.lpips, p.dataset, p.scene
            )
        });
        if r.error.is_some() {
            out.push_str(&format!("| {} | failed | | | | | | | | | {paper} |\n", r.name));
            continue;
        }
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {paper} |\n",
            r.name,
            cell(r.psnr, 2),
            cell(r.ssim, 4),
            r.lpips
                .as_ref()
                .map_or("-".into(), |(net, d)| format!("{d:.4} ({net})")),
            r.masked.map_or("-".into(), |(p, s)| format!("{p:.2} / {s:.4}")),
            r.test_views.map_or("-".into(), |n| n.to_string()),
            cell(r.train_seconds, 1),
            r.iterations.map_or("-".into(), |n| n.to_string()),
            r.billboards.map_or("-".into(), |n| n.to_string()),
            cell(r.peak_rss_bytes.map(|b| b as f64 / 1e6), 0),
        ));
    }
    for r in rows {
        if let Some(error) = &r.error {
            out.push_str(&format!(
                "\n{} ({}) failed: {}\n",
                r.name,
                r.scene,
                error.replace('\n', " ")
            ));
        }
    }
    out
}
