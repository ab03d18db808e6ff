//! # bbsplat
//!
//! Billboard splatting (BBSplat) on the CPU: planar primitives carrying a small learned RGB
//! texture, an alpha texture and spherical-harmonics colour, rendered by ray-plane intersection
//! and front-to-back alpha compositing, and trained by gradient descent.
//!
//! The crate is built from small pure stages, each with a forward pass and an analytic backward
//! pass (a vector-Jacobian product) that is checked against central finite differences by the
//! `gradcheck` module (feature `testing`). Conventions (frames, units, ranges, thresholds) are
//! collected in `docs/numerics.md`; every module states the ones it relies on.
//!
//! # The front door
//!
//! The crate root re-exports what a program embedding the crate needs, from loading a dataset to
//! rendering a trained model; the modules they come from hold the rest (schedules, losses,
//! stages, formats):
//!
//! | step | items | module |
//! |---|---|---|
//! | load posed photographs (COLMAP, NeRF-synthetic, instant-ngp, NeuS/IDR, LLFF; object masks) | [`load`], [`LoadOptions`], [`Scene`], [`SceneError`] | [`scene`] |
//! | the settings `bbsplat train` would use, chosen for the scene and the run length, each with its reason | [`TrainPlan`], [`TrainRequest`], [`RunLength`], [`load_with_data_background`] | [`plan`] |
//! | initial billboards from the scene's points | [`TrainPlan::init_model`], [`init_model`], [`InitError`] | [`init`] |
//! | the three forms of the billboard set: raw optimised parameters (saved), activated (owned), activated (borrowed, what the renderer reads) | [`RawBillboards`], [`ActivatedBillboards`], [`ActivatedRef`] | [`model`], [`billboards`], [`raster`] |
//! | train: the whole run (evaluations, checkpoints, stop requests) or single steps | [`run`], [`RunConfig`], [`TrainEvent`], [`RunOutcome`], [`RunError`], [`StopSignal`], [`Trainer`], [`TrainConfig`], [`TrainView`] | [`train`] |
//! | model folders in the reference's format (PLY + 8-bit npz textures) | [`save_model`], [`load_model`], [`ModelMeta`], [`ModelFileError`] | [`model_file`] |
//! | render, and back-propagate an image gradient | [`render`], [`render_backward`], [`RenderSettings`], [`RenderOutput`], [`Camera`] | [`raster`], [`camera`] |
//!
//! A whole round trip: a small dataset on disk (here the embedded demo scene written as a COLMAP
//! model, feature `tools`; any dataset folder loads the same way), loaded, planned as `bbsplat
//! train` plans it, initialised, trained for a few steps, saved, loaded back and rendered.
//! Images are linear RGB in `[0, 1]`, interleaved, rows from the top; cameras are
//! world-to-camera with OpenCV axes (x right, y down, z forward).
//!
//! ```
//! use bbsplat::{
//!     LoadOptions, ModelMeta, RenderSettings, RunLength, RunOutcome, StopSignal, TrainEvent, TrainPlan,
//!     TrainRequest, TrainView, load_model, load_with_data_background, render, run, save_model,
//! };
//! use bbsplat::demo::{DemoConfig, export_colmap, generate};
//! use glam::Vec3;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = std::env::temp_dir().join(format!("bbsplat-front-door-{}", std::process::id()));
//! let demo = generate(&DemoConfig { resolution: 24, train_views: 7, test_views: 1, points: 300, seed: 0 });
//! export_colmap(&demo, &dir.join("data"))?;
//!
//! // Load: 8 views, every 8th held out for testing, images undistorted to pinhole cameras, the
//! // background chosen from the data.
//! let (scene, background) = load_with_data_background(&dir.join("data"), &LoadOptions::default())?;
//! assert_eq!((scene.train.len(), scene.test.len()), (7, 1));
//!
//! // Plan 30 steps with 4×4 textures; the rest (billboard count, growth, initialisation,
//! // learning rates, coarse-to-fine) is chosen from the scene, as `bbsplat train` does.
//! let request = TrainRequest { length: RunLength::Steps(30), texture_size: 4, ..TrainRequest::default() };
//! let plan = TrainPlan::new(&scene, Some(&background), &request)?;
//! assert!(plan.choices.iter().any(|c| c.setting == "billboards"));
//! let (model, _report) = plan.init_model(&scene)?;
//! let mut trainer = plan.trainer(model);
//! let (train, test) = (TrainView::from_views(&scene.train), TrainView::from_views(&scene.test));
//! let mut steps = 0;
//! // No output folder: nothing is written, the final evaluation renders the float model.
//! let outcome = run(&mut trainer, &train, &test, &plan.run_config(), &StopSignal::new(), |event| {
//!     if let TrainEvent::Step { .. } = event {
//!         steps += 1;
//!     }
//! })?;
//! let RunOutcome::Finished(summary) = outcome else { panic!("nothing asked the run to stop") };
//! assert_eq!(steps, 30);
//! assert!(summary.test_psnr.is_finite());
//!
//! // Save the model folder (8-bit textures) and load it back.
//! let model = trainer.export_model();
//! let meta = ModelMeta::for_model(&model, 3, scene.background.rgb());
//! save_model(&dir.join("model"), &model, &meta)?;
//! let (loaded, meta) = load_model(&dir.join("model"))?;
//! assert_eq!(loaded.len(), model.len());
//!
//! // Render the held-out view with the settings the model was saved with.
//! let settings = RenderSettings {
//!     background: Vec3::from_array(meta.background),
//!     sh_degree: meta.sh_degree,
//!     ..RenderSettings::default()
//! };
//! let camera = scene.test[0].camera;
//! let out = render(&loaded.activate().borrowed(), &camera, &settings);
//! assert_eq!(out.rgb.len(), camera.pixel_count() * 3);
//! assert!(out.rgb.iter().all(|v| v.is_finite()));
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```
//!
//! [`TrainConfig::default`] alone is the reference's configuration (32 000 steps at its learning
//! rates, no growth, full resolution); [`init_model`] the reference's initialisation. They are
//! there for ablations and tests; short runs do much better with the plan.
//!
//! # Features
//!
//! - `cli` (default): the `bbsplat` binary and its dependencies (clap, indicatif, ctrlc,
//!   anyhow); enables `tools`.
//! - `tools`: the embedded demo scene (`demo`), the budget/setting sweep tool (`sweep`, with
//!   plotters for its SVG plots) and the process-CPU clock of the benchmark harnesses
//!   (`report::process_cpu_ms`).
//! - `testing`: the gradient checker (`gradcheck`), the proptest strategies (`strategies`, with
//!   proptest), the parser fuzzing entry points (`scene::fuzz`) and `testing_internals`
//!   (crate-private kernels the test suite checks directly; not an API).
//!
//! Without features (`default-features = false`) the crate is the core above (scene input,
//! initialisation, model, training, model files, rendering, evaluation), built on glam, rayon,
//! image, serde, serde_json, thiserror, miniz_oxide, crc32fast and libc.

#![deny(missing_docs)]
#![warn(clippy::undocumented_unsafe_blocks, clippy::missing_safety_doc)]
// Numeric kernels index several parallel arrays with one loop counter; iterator chains would hide
// the index arithmetic the docs describe.
#![allow(clippy::needless_range_loop)]

pub mod benchmark;
pub mod billboards;
pub mod blocks;
pub mod camera;
pub mod cpu;
#[cfg(feature = "tools")]
pub mod demo;
pub mod eval;
pub mod exp_f32;
pub mod export;
#[cfg(feature = "fault-injection")]
pub mod fault;
#[cfg(not(feature = "fault-injection"))]
mod fault;
pub mod file_io;
pub mod fnv;
#[cfg(feature = "testing")]
pub mod gradcheck;
pub mod init;
pub mod kdtree;
pub mod loss;
pub mod lpips;
pub mod memory;
pub mod mesh;
pub mod model;
pub mod model_file;
pub mod plan;
pub mod raster;
pub mod report;
pub mod rng;
pub mod scene;
pub mod stages;
#[cfg(feature = "testing")]
pub mod strategies;
#[cfg(feature = "tools")]
pub mod sweep;
#[cfg(feature = "testing")]
pub mod testing_internals;
pub mod train;
pub mod zipfile;

/// The README's Rust examples, compiled by `cargo test` (a doctest each).
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

pub use billboards::ActivatedBillboards;
pub use camera::Camera;
pub use init::scene_init::{InitError, init_model};
pub use model::RawBillboards;
pub use model_file::{ModelFileError, ModelMeta, load_model, save_model};
pub use plan::{RunLength, TrainPlan, TrainRequest};
pub use raster::{ActivatedRef, RenderOutput, RenderSettings, render, render_backward};
pub use scene::data_background::load_with_data_background;
pub use scene::{LoadOptions, Scene, SceneError, load};
pub use train::run::run;
pub use train::{RunConfig, RunError, RunOutcome, StopSignal, TrainConfig, TrainEvent, TrainView, Trainer};
