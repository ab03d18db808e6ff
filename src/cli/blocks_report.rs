//! `bbsplat blocks report DIR`: the report of a block-wise chain run by `bbsplat blocks run`
//! (its folder layout: [`super::blocks_chain`]), written as `DIR/report.json` and printed: each
//! stage's time and figures, the overlap factor, the final test figures (the polish's), and the
//! chain's wall time on 1 to 64 machines ([`bbsplat::blocks::wall_time`]).
//!
//! Times are the trainings' step seconds (`train_seconds` of their summaries: loading,
//! evaluation and saving are not counted) and the wall seconds the split and the merge record
//! themselves.

use super::blocks_files::{MERGE_FILE, MergeRecord, block_dir, read_plan};
use anyhow::{Context, Result};
use bbsplat::benchmark::BenchmarkRow;
use bbsplat::blocks::wall_time::chain_wall_time;
use bbsplat::train::run::SUMMARY_FILE;
use clap::Args;
use serde::Serialize;
use std::path::Path;

/// The report's file in the chain's folder.
pub const REPORT_FILE: &str = "report.json";

/// Flags of `bbsplat blocks report`.
#[derive(Args, Clone, Debug)]
pub struct ReportArgs {
    /// The chain's folder (`bbsplat blocks run -o`).
    pub chain: std::path::PathBuf,
}

/// One training of the chain.
#[derive(Clone, Debug, Serialize)]
struct StageFigures {
    steps: usize,
    seconds: f64,
    billboards: usize,
    test_psnr: Option<f64>,
    test_ssim: Option<f64>,
    test_views: Option<usize>,
}

/// The chain's wall time on some machines.
#[derive(Clone, Debug, Serialize)]
struct WallTime {
    machines: usize,
    seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
struct Report {
    cells: usize,
    overlap_factor: f64,
    coarse: StageFigures,
    split_seconds: f64,
    blocks: Vec<StageFigures>,
    merge_seconds: f64,
    merged_billboards: usize,
    polish: StageFigures,
    /// Every stage's seconds summed (the chain on one machine).
    total_seconds: f64,
    wall_time: Vec<WallTime>,
}

fn figures(run: &Path) -> Result<StageFigures> {
    let path = run.join(SUMMARY_FILE);
    let row = BenchmarkRow::from_summary("", "", &path).with_context(|| format!("reading {}", path.display()))?;
    Ok(StageFigures {
        steps: row.iterations.unwrap_or(0),
        seconds: row.train_seconds.unwrap_or(0.0),
        billboards: row.billboards.unwrap_or(0),
        test_psnr: row.psnr,
        test_ssim: row.ssim,
        test_views: row.test_views,
    })
}

/// Runs `bbsplat blocks report`.
pub fn run(args: &ReportArgs) -> Result<()> {
    let dir = &args.chain;
    let blocks_dir = dir.join("blocks");
    let plan = read_plan(&blocks_dir)?;
    let merge_path = blocks_dir.join(MERGE_FILE);
    let merge: MergeRecord = serde_json::from_str(&bbsplat::file_io::read_text_bounded(
        &merge_path,
        bbsplat::file_io::JSON_FILE,
    )?)
    .with_context(|| format!("{}: not a merge record", merge_path.display()))?;
    let coarse = figures(&dir.join("coarse"))?;
    let blocks = (0..plan.blocks.len())
        .map(|k| figures(&block_dir(&blocks_dir, k).join("run")))
        .collect::<Result<Vec<_>>>()?;
    let polish = figures(&dir.join("polish"))?;
    let before = coarse.seconds + plan.seconds;
    let after = merge.seconds + polish.seconds;
    let block_seconds: Vec<f64> = blocks.iter().map(|b| b.seconds).collect();
    let machines = [1, 2, 4, 8, 16, 32, 64];
    let wall_time: Vec<WallTime> = machines
        .iter()
        .filter(|&&m| m == 1 || m / 2 < blocks.len())
        .map(|&m| WallTime {
            machines: m,
            seconds: chain_wall_time(before, &block_seconds, after, m),
        })
        .collect();
    let report = Report {
        cells: plan.blocks.len(),
        overlap_factor: plan.overlap_factor,
        split_seconds: plan.seconds,
        merge_seconds: merge.seconds,
        merged_billboards: merge.kept.iter().sum(),
        total_seconds: before + block_seconds.iter().sum::<f64>() + after,
        coarse,
        blocks,
        polish,
        wall_time,
    };
    let json = serde_json::to_string_pretty(&report).context("encoding the report")?;
    bbsplat::file_io::write_atomic(&dir.join(REPORT_FILE), json.as_bytes())?;
    let psnr = report
        .polish
        .test_psnr
        .map_or("-".to_string(), |p| format!("{p:.2} dB"));
    println!(
        "{} blocks (overlap factor {:.2}), {} billboards merged; after the polish: test PSNR {psnr}",
        report.cells, report.overlap_factor, report.merged_billboards
    );
    let times: Vec<String> = report
        .wall_time
        .iter()
        .map(|w| format!("{} machine(s) {:.1} s", w.machines, w.seconds))
        .collect();
    println!("wall time: {}", times.join(", "));
    println!("wrote {}", dir.join(REPORT_FILE).display());
    Ok(())
}
