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

/// Writes `bytes` to `path` through `<path>.tmp` and a rename, so readers never see a partial
/// file. Errors name the file that failed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|source| SweepError::Io {
        path: tmp.clone(),
        source,
    })?;
    std::fs::rename(&tmp, path).map_err(|source| SweepError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Model size in bytes as a Pareto cost; 0 (the trainer saved no model) is unknown (NaN), so
/// such a run is never on the size front.
pub(crate) fn size_cost(bytes: u64) -> f64 {
    if bytes == 0 { f64::NAN } else { bytes as f64 }
}

/// Pareto flags per record: (PSNR vs training time, PSNR vs model size).
fn fronts(records: &[SweepRecord]) -> (Vec<bool>, Vec<bool>) {
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
model_bytes,peak_rss_bytes,pareto_time,pareto_size";

/// The records as CSV with header [`CSV_HEADER`]: one row per record, in order. Iterations,
/// billboards, texture size and seed are the values the run reports; `max_width`,
/// `texture_threshold` and `texture_mode` are the requested flags (empty: trainer default).
/// Units: seconds, milliseconds, bytes, dB. The Pareto columns are `1` or `0`.
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

fn csv_field(f: &str) -> String {
    if f.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", f.replace('"', "\"\""))
    } else {
        f.to_string()
    }
}

/// The records as a markdown table, in order: budget, measured speed and quality, and a Pareto
/// column naming the fronts the run is on (`time`: PSNR vs training time, `size`: PSNR vs model
/// size). Model size and peak RSS in MB (10⁶ bytes); `n/a` where the summary has 0 (no model saved,
/// or no peak-RSS reading on the platform), and such a run is on no size front.
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
         PSNR dB | SSIM | model MB | peak RSS MB | Pareto |\n\
         |---|--:|--:|--:|--:|---|--:|---|--:|--:|--:|--:|--:|--:|---|\n",
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
            "| {} | {} | {} | {} | {} | {} | {} | {}×{} | {:.1} | {:.2} | {:.2} | {:.4} | {} | {} | {} |",
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::TrainSummary;
    use crate::sweep::{Setting, fake, run_grid};

    fn records() -> Vec<SweepRecord> {
        run_grid(&fake::grid(), |s| Ok(fake::summary(s))).unwrap().records
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bbsplat-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn csv_has_one_parsable_row_per_record_and_marks_fronts() {
        let recs = records();
        let csv = csv_table(&recs);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(lines.len(), recs.len() + 1);
        let header: Vec<&str> = CSV_HEADER.split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let time_points: Vec<(f64, f64)> = recs
            .iter()
            .map(|r| (r.summary.train_seconds, r.summary.test_psnr))
            .collect();
        let front = pareto_front(&time_points);
        for (i, (line, r)) in lines[1..].iter().zip(&recs).enumerate() {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), header.len());
            assert_eq!(f[col("slug")], r.setting.slug());
            assert_eq!(f[col("test_psnr")].parse::<f64>().unwrap(), r.summary.test_psnr);
            assert_eq!(f[col("model_bytes")].parse::<u64>().unwrap(), r.summary.model_bytes);
            assert_eq!(f[col("texture_mode")], r.setting.texture_mode.unwrap().as_str());
            assert_eq!(f[col("max_width")], "");
            assert_eq!(f[col("pareto_time")] == "1", front.contains(&i));
        }
    }

    #[test]
    fn csv_quotes_fields_that_need_it() {
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv_field("plain"), "plain");
    }

    #[test]
    fn markdown_table_rows_and_pareto_column() {
        let recs = records();
        let table = markdown_table(&recs);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), recs.len() + 2);
        // Every row has the header's column count.
        let cols = lines[0].matches('|').count();
        assert!(lines.iter().all(|l| l.matches('|').count() == cols));
        // The fastest run is on the time front; it has the smallest model, but so has the longer
        // run with the same budget, which is better: only that one is on the size front.
        let row = |slug: &str| *lines.iter().find(|l| l.starts_with(&format!("| {slug} |"))).unwrap();
        assert!(row("it500_bb1000_gaussian").ends_with("| time |"), "{table}");
        assert!(row("it2000_bb1000_gaussian").ends_with("size |"), "{table}");
        // A run that is slower and worse than another is not on the time front.
        let get = |slug: &str| &recs.iter().find(|r| r.setting.slug() == slug).unwrap().summary;
        let (slow, fast) = (get("it2000_bb1000_full"), get("it500_bb3000_full"));
        assert!(fast.train_seconds < slow.train_seconds && fast.test_psnr > slow.test_psnr);
        assert!(!row("it2000_bb1000_full").contains("time"), "{table}");
        // PSNR with two decimals, model size in MB.
        let r = get("it2000_bb3000_full");
        assert!(row("it2000_bb3000_full").contains(&format!("| {:.2} |", r.test_psnr)));
        assert!(row("it2000_bb3000_full").contains(&format!("| {:.2} |", r.model_bytes as f64 / 1e6)));
    }

    #[test]
    fn unknown_model_size_is_on_no_size_front() {
        let mut recs = records();
        // The best run by PSNR saved no model.
        let best = (0..recs.len())
            .max_by(|&a, &b| recs[a].summary.test_psnr.total_cmp(&recs[b].summary.test_psnr))
            .unwrap();
        recs[best].summary.model_bytes = 0;
        recs[best].summary.peak_rss_bytes = 0;
        let (time, size) = fronts(&recs);
        assert!(time[best] && !size[best]);
        let table = markdown_table(&recs);
        let row = table.lines().nth(best + 2).unwrap();
        assert!(row.ends_with("| n/a | n/a | time |"), "{row}");
    }

    #[test]
    fn write_outputs_writes_every_file_atomically() {
        let dir = temp_dir("outputs");
        let recs = records();
        let files = write_outputs(&dir.join("report"), &recs).unwrap();
        for p in [
            &files.csv,
            &files.json,
            &files.markdown,
            &files.psnr_vs_time,
            &files.psnr_vs_size,
            &files.curves,
        ] {
            assert!(std::fs::metadata(p).unwrap().len() > 100, "{}", p.display());
        }
        let leftovers: Vec<_> = std::fs::read_dir(dir.join("report"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        assert_eq!(std::fs::read_to_string(&files.csv).unwrap(), csv_table(&recs));
        assert_eq!(std::fs::read_to_string(&files.markdown).unwrap(), markdown_table(&recs));
        // The JSON reads back into the same records.
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&files.json).unwrap()).unwrap();
        let rows = v["records"].as_array().unwrap();
        assert_eq!(rows.len(), recs.len());
        for (row, r) in rows.iter().zip(&recs) {
            assert_eq!(row["slug"], r.setting.slug());
            let setting: Setting = serde_json::from_value(row["setting"].clone()).unwrap();
            let summary: TrainSummary = serde_json::from_value(row["summary"].clone()).unwrap();
            assert_eq!(&setting, &r.setting);
            assert_eq!(&summary, &r.summary);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn write_errors_name_the_file() {
        let dir = temp_dir("blocked");
        std::fs::create_dir_all(&dir).unwrap();
        // A directory where the CSV's temp file should go makes the write fail.
        std::fs::create_dir_all(dir.join("sweep.csv.tmp")).unwrap();
        let err = write_outputs(&dir, &records()).unwrap_err().to_string();
        assert!(err.contains("sweep.csv.tmp"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
