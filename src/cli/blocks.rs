//! The `bbsplat blocks` subcommands, and two of them, `split` and `merge`: the stages of a scene
//! trained as spatial blocks ([`bbsplat::blocks`], docs/cluster.md "Tier 2") that are not
//! `bbsplat train` runs (`run` is `cli/blocks_chain.rs`, `report` `cli/blocks_report.rs`, the
//! files they share `cli/blocks_files.rs`).
//!
//! `split SCENE --coarse MODEL -o BLOCKS` cuts the ground plane into a grid of cells, chooses
//! each block's views from the coarse model and writes `BLOCKS/blocks.json` (the partition,
//! each block's views and initial billboard count, the overlap factor) and per block
//! `BLOCKS/block_K/init/` (the coarse billboards of its cell and margin) and
//! `BLOCKS/block_K/views.txt` (its training and test views). Each block then trains as
//! `bbsplat train SCENE -o BLOCKS/block_K/run --init-model BLOCKS/block_K/init --views
//! BLOCKS/block_K/views.txt`, and `merge BLOCKS -o MODEL` joins their `run/model/` folders.

use super::blocks_files::{
    Balance, BlockEntry, BlocksPlan, MERGE_FILE, MergeRecord, PLAN_FILE, block_dir, grid, read_plan,
};
use super::common::SceneArgs;
use anyhow::{Context, Result};
use bbsplat::blocks::{self, GroundFrame, Partition};
use bbsplat::model_file::{ModelMeta, load_model, save_model};
use bbsplat::raster::RenderSettings;
use clap::{Args, Subcommand};
use glam::Vec3;
use std::path::PathBuf;

/// The stages of a block-wise training.
#[derive(Subcommand, Clone, Debug)]
pub enum BlocksCommand {
    /// Partition a scene for block-wise training from a coarse model of it.
    Split(SplitArgs),
    /// Join the trained blocks' models, each keeping the billboards inside its own cell.
    Merge(MergeArgs),
    /// Run the whole chain (coarse run, split, blocks, merge, polish, report) here, stage after
    /// stage, or write it as Slurm jobs (`--slurm`).
    Run(super::blocks_chain::ChainArgs),
    /// Write a chain's report: each stage's time and figures, and its wall time on K machines.
    Report(super::blocks_report::ReportArgs),
    /// Measure the test views where the cells meet, for the chain's model and other models.
    Seams(super::blocks_seams::SeamsArgs),
}

/// Flags of `bbsplat blocks split`.
#[derive(Args, Clone, Debug)]
pub struct SplitArgs {
    /// The dataset, as `bbsplat train` reads it (with the same scene flags).
    pub scene: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// The coarse model of the whole scene (a `bbsplat train` output's `model/`).
    #[arg(long)]
    pub coarse: PathBuf,
    /// The blocks folder to write (blocks.json, block_K/init/, block_K/views.txt).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Cells along the cameras' main spread × across it.
    #[arg(long, default_value = "2x1", value_parser = grid)]
    pub grid: (usize, usize),
    /// How far a block reaches past its cell, as a fraction of the mean cell length along.
    #[arg(long, default_value_t = 0.2)]
    pub margin: f32,
    /// A view trains a block when at least this share of its rendered impact falls in the
    /// block's cell and margin.
    #[arg(long, default_value_t = 0.1)]
    pub min_share: f64,
    /// What the cells are balanced by.
    #[arg(long, value_enum, default_value_t = Balance::Cameras)]
    pub balance: Balance,
    /// Turn the grid by this many degrees about up, from the cameras' main spread towards
    /// across it (for a capture whose main spread is not the way to cut it).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub turn: f32,
}

/// Flags of `bbsplat blocks merge`.
#[derive(Args, Clone, Debug)]
pub struct MergeArgs {
    /// The blocks folder `split` wrote, each block trained into `block_K/<RUN>/`.
    pub blocks: PathBuf,
    /// The merged model folder to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The run folder of each block, inside `block_K/`.
    #[arg(long, default_value = "run")]
    pub run: String,
}

/// Runs a `bbsplat blocks` stage.
pub fn run(command: BlocksCommand) -> Result<()> {
    match command {
        BlocksCommand::Split(args) => split(&args),
        BlocksCommand::Merge(args) => merge(&args),
        BlocksCommand::Run(args) => super::blocks_chain::run(&args),
        BlocksCommand::Report(args) => super::blocks_report::run(&args),
        BlocksCommand::Seams(args) => super::blocks_seams::run(&args),
    }
}

fn split(args: &SplitArgs) -> Result<()> {
    let start = std::time::Instant::now();
    anyhow::ensure!(
        args.min_share.is_finite() && (0.0..=1.0).contains(&args.min_share),
        "--min-share must be a fraction from 0 to 1 (got {})",
        args.min_share
    );
    let (coarse, meta) =
        load_model(&args.coarse).with_context(|| format!("reading --coarse {}", args.coarse.display()))?;
    let (scene, _) = args.scene_args.load_for_training(&args.scene)?;
    let frame = GroundFrame::from_cameras(scene.train.iter().map(|v| &v.camera))
        .with_context(|| format!("{}: the scene has no training view", args.scene.display()))?;
    anyhow::ensure!(
        args.turn.is_finite(),
        "--turn must be a finite angle in degrees (got {})",
        args.turn
    );
    let frame = frame.turned(args.turn);
    let points: Vec<glam::Vec2> = match args.balance {
        Balance::Cameras => scene.train.iter().map(|v| frame.project(v.camera.centre())).collect(),
        Balance::Billboards => coarse.positions.iter().map(|&p| frame.project(p)).collect(),
    };
    let (columns, rows) = args.grid;
    let partition = Partition::balanced(frame, &points, columns, rows, args.margin)
        .with_context(|| format!("--grid {columns}x{rows} --balance {:?}", args.balance))?;
    let settings = RenderSettings {
        background: Vec3::from_array(meta.background),
        sh_degree: meta.sh_degree,
        ..RenderSettings::default()
    };
    let choose = |views: &[bbsplat::scene::View]| {
        let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
        let shares = blocks::impact_shares(&coarse, &cameras, &settings, &partition);
        let chosen = blocks::choose_views(&shares, &cameras, &partition, args.min_share);
        let names: Vec<Vec<String>> = chosen
            .iter()
            .map(|block| block.iter().map(|&v| views[v].name.clone()).collect())
            .collect();
        (names, blocks::overlap_factor(&chosen, views.len()))
    };
    let (train_views, overlap_factor) = choose(&scene.train);
    let (test_views, _) = choose(&scene.test);
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let mut entries = Vec::new();
    for (cell, (train, test)) in train_views.into_iter().zip(test_views).enumerate() {
        let dir = block_dir(&args.output, cell);
        let init = blocks::block_init(&partition, &coarse, cell);
        anyhow::ensure!(
            !init.is_empty(),
            "block {cell}: no billboard of the coarse model lies in its cell or margin; use fewer cells or a wider --margin"
        );
        let init_meta = ModelMeta {
            billboards: init.len(),
            scene: None,
            ..meta.clone()
        };
        save_model(&dir.join("init"), &init, &init_meta)
            .with_context(|| format!("writing block {cell}'s initial model"))?;
        let mut list = format!("# the views of block {cell} ({})\n", PLAN_FILE);
        for name in train.iter().chain(&test) {
            list.push_str(name);
            list.push('\n');
        }
        bbsplat::file_io::write_atomic(&dir.join("views.txt"), list.as_bytes())?;
        println!(
            "block {cell}: {} billboards, {} training and {} test views",
            init.len(),
            train.len(),
            test.len()
        );
        entries.push(BlockEntry {
            cell,
            init_billboards: init.len(),
            train_views: train,
            test_views: test,
        });
    }
    println!("overlap factor {overlap_factor:.3} (training views per block summed, over the training views)");
    let plan = BlocksPlan {
        scene: args.scene.clone(),
        coarse: args.coarse.clone(),
        grid: args.grid,
        margin_fraction: args.margin,
        min_share: args.min_share,
        balance: args.balance,
        partition,
        overlap_factor,
        blocks: entries,
        seconds: start.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&plan).context("encoding the blocks plan")?;
    bbsplat::file_io::write_atomic(&args.output.join(PLAN_FILE), json.as_bytes())?;
    Ok(())
}

/// Merges the blocks one at a time (loaded, cut to their own cell, appended, dropped), so that
/// at most one block's model is held beside the merged one.
fn merge(args: &MergeArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let plan = read_plan(&args.blocks)?;
    let mut merged: Option<(bbsplat::RawBillboards, ModelMeta)> = None;
    let (mut kept, mut trained) = (Vec::new(), Vec::new());
    for block in &plan.blocks {
        let dir = block_dir(&args.blocks, block.cell)
            .join(&args.run)
            .join(bbsplat::train::run::MODEL_DIR);
        let (model, meta) = load_model(&dir).with_context(|| format!("reading block {}'s model", block.cell))?;
        let own = blocks::own_cell(&plan.partition, &model, block.cell);
        println!(
            "block {}: {} of its {} billboards inside its cell",
            block.cell,
            own.len(),
            model.len()
        );
        kept.push(own.len());
        trained.push(model.len());
        match &mut merged {
            None => merged = Some((own, meta)),
            Some((all, first)) => {
                anyhow::ensure!(
                    (first.sh_degree, first.background, first.texture_size)
                        == (meta.sh_degree, meta.background, meta.texture_size),
                    "{}: SH degree, background or texture size differ from block 0's",
                    dir.display()
                );
                bbsplat::train::grow::append_rows(all, &own);
            }
        }
    }
    let (merged, first) = merged.expect("a plan has at least one block");
    let meta = ModelMeta {
        billboards: merged.len(),
        scene: None,
        ..first
    };
    save_model(&args.output, &merged, &meta).with_context(|| format!("writing {}", args.output.display()))?;
    println!("merged model: {} billboards in {}", merged.len(), args.output.display());
    let record = MergeRecord {
        kept,
        trained,
        seconds: start.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&record).context("encoding the merge record")?;
    bbsplat::file_io::write_atomic(&args.blocks.join(MERGE_FILE), json.as_bytes())?;
    Ok(())
}
