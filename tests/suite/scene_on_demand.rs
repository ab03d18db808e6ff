//! Images decoded on demand (`scene::on_demand`): the loader's choice by the image budget, the
//! same pixels as in memory, a run bit-identical to the in-memory run (coarse-to-fine and error
//! growth included), the cache's bound, and an image changed or removed after loading refused
//! with an error naming it (the step not taken).

use crate::scene_support::*;
use bbsplat::model::RawBillboards;
use bbsplat::scene::on_demand::ImageCache;
use bbsplat::scene::{LoadOptions, Scene, ViewImage, load};
use bbsplat::train::resolution::ResolutionSchedule;
use bbsplat::train::{RunConfig, RunError, StopSignal, TrainConfig, TrainError, TrainView, Trainer, ViewPixels, run};
use glam::Vec3;
use std::path::Path;

/// Views of the dataset (12 images of 32×24: half PINHOLE, half SIMPLE_RADIAL, undistorted).
const VIEWS: usize = 12;
/// Bytes of one loaded image (the undistorted ones are cropped, so at most this).
const IMAGE_BYTES: u64 = 32 * 24 * 3;

fn options(image_memory: u64) -> LoadOptions {
    LoadOptions {
        test_every: 4,
        print_warnings: false,
        image_memory,
        ..LoadOptions::default()
    }
}

fn on_demand_views(scene: &Scene) -> usize {
    scene
        .train
        .iter()
        .chain(&scene.test)
        .filter(|v| matches!(v.image, ViewImage::OnDemand(_)))
        .count()
}

#[test]
fn the_budget_chooses_memory_or_on_demand_and_both_give_the_same_pixels() {
    let dir = temp_dir("on_demand_pixels");
    colmap_dataset(&dir, VIEWS, true);
    let memory = load(&dir, &options(u64::MAX)).unwrap();
    let total: u64 = memory
        .train
        .iter()
        .chain(&memory.test)
        .map(|v| v.image.held_bytes())
        .sum();
    assert!(total > 0 && total <= VIEWS as u64 * IMAGE_BYTES);
    assert_eq!(on_demand_views(&memory), 0);
    assert!(memory.image_cache().is_none());
    assert_eq!(memory.image_bytes(), total);
    // Exactly the images' bytes still fit; one byte less does not.
    let fits = load(&dir, &options(total)).unwrap();
    assert_eq!(on_demand_views(&fits), 0);
    let budget = total - 1;
    let lazy = load(&dir, &options(budget)).unwrap();
    assert_eq!(on_demand_views(&lazy), VIEWS);
    assert_eq!(lazy.image_bytes(), budget);
    let cache = lazy.image_cache().unwrap().clone();
    assert!(cache.stats().peak_bytes <= budget);
    for (a, b) in memory
        .train
        .iter()
        .chain(&memory.test)
        .zip(lazy.train.iter().chain(&lazy.test))
    {
        assert_eq!(
            (&a.name, a.camera, &a.mask, &a.coverage),
            (&b.name, b.camera, &b.mask, &b.coverage)
        );
        assert_eq!(
            a.image.get().unwrap().as_bytes(),
            b.image.get().unwrap().as_bytes(),
            "{}",
            a.name
        );
    }
    let stats = cache.stats();
    assert!(stats.misses > 0 && stats.hits > 0, "{stats:?}");
    assert!(stats.peak_bytes <= budget && stats.held_bytes <= budget, "{stats:?}");
    // A budget of 0 keeps nothing: every image is decoded each time, the same pixels still.
    let none = load(&dir, &options(0)).unwrap();
    assert_eq!(on_demand_views(&none), VIEWS);
    assert_eq!(none.image_cache().unwrap().stats().peak_bytes, 0);
    assert_eq!(
        none.train[3].image.get().unwrap().as_bytes(),
        memory.train[3].image.get().unwrap().as_bytes()
    );
}

#[test]
fn the_cache_drops_the_least_recently_used_image_first() {
    let image = |v: u8| std::sync::Arc::new(bbsplat::scene::Image::new(2, 2, vec![v; 12]).unwrap());
    let cache = ImageCache::new(36);
    for k in 0..3 {
        cache.insert(k, image(k as u8));
    }
    assert!(cache.get(0).is_some());
    cache.insert(3, image(3)); // 1 is the least recently used
    assert!(cache.get(1).is_none());
    assert!(cache.get(2).is_some() && cache.get(0).is_some() && cache.get(3).is_some());
    // Larger than the whole budget: handed out, not kept; nothing else leaves.
    cache.insert(
        9,
        std::sync::Arc::new(bbsplat::scene::Image::new(4, 4, vec![0; 48]).unwrap()),
    );
    assert!(cache.get(9).is_none());
    assert_eq!(cache.stats().held_bytes, 36);
    assert_eq!(cache.stats().peak_bytes, 36);
    // Replacing a key's image counts its bytes once.
    cache.insert(0, image(7));
    assert_eq!(cache.stats().held_bytes, 36);
    assert_eq!(cache.get(0).unwrap().as_bytes()[0], 7);
}

/// A trainer for `scene` with growth (error placement and its depth sweep included).
fn trainer(scene: &Scene, iterations: usize) -> Trainer {
    // 60 points on a lattice around the origin, which the cameras look at.
    let points: Vec<Vec3> = (0..60)
        .map(|k| Vec3::new((k % 4) as f32, ((k / 4) % 5) as f32, (k / 20) as f32) * 0.3 - Vec3::splat(0.45))
        .collect();
    let colours = vec![[0.5f32; 3]; points.len()];
    let model = RawBillboards::from_points(&points, &colours, 4, 3);
    let config = TrainConfig {
        iterations,
        seed: 3,
        extent: scene.extent,
        relocate_every: 8,
        growth_cap: 90,
        error_growth: 0.5,
        ..TrainConfig::default()
    };
    Trainer::new(model, config)
}

fn run_config() -> RunConfig {
    RunConfig {
        eval_every: 16,
        resolution: ResolutionSchedule { factor: 2, until: 0.5 },
        ..RunConfig::default()
    }
}

/// The trainer after a whole run (coarse first half) on `scene`, and its final test PSNR.
fn trained(scene: &Scene) -> (Trainer, f64) {
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_view).collect();
    let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_view).collect();
    let mut t = trainer(scene, 48);
    let outcome = run(&mut t, &train, &test, &run_config(), &StopSignal::new(), |_| {}).unwrap();
    let psnr = match outcome {
        bbsplat::train::RunOutcome::Finished(summary) => summary.test_psnr,
        other => panic!("{other:?}"),
    };
    (t, psnr)
}

#[test]
fn a_run_on_demand_is_bit_identical_to_the_run_in_memory() {
    let dir = temp_dir("on_demand_run");
    colmap_dataset(&dir, VIEWS, true);
    let memory = load(&dir, &options(u64::MAX)).unwrap();
    // Room for two images: most steps decode their view again.
    let lazy = load(&dir, &options(2 * IMAGE_BYTES)).unwrap();
    assert_eq!(on_demand_views(&lazy), VIEWS);
    let from_view = TrainView::from_view(&lazy.train[0]);
    assert!(matches!(from_view.rgb, ViewPixels::OnDemand(_)) && from_view.rgb.bytes() == 0);
    let (a, psnr_a) = trained(&memory);
    let (b, psnr_b) = trained(&lazy);
    assert!(a.model().len() > 60, "growth ran: {} billboards", a.model().len());
    assert_eq!(a.checkpoint_bytes(), b.checkpoint_bytes());
    assert_eq!(psnr_a.to_bits(), psnr_b.to_bits());
    let stats = lazy.image_cache().unwrap().stats();
    assert!(stats.misses >= 24, "the views were decoded again: {stats:?}");
    assert!(stats.peak_bytes <= 2 * IMAGE_BYTES, "{stats:?}");
}

/// Overwrites the image of `view` with another pattern (same size).
fn repaint(path: &Path) {
    let img = image::open(path).unwrap().into_rgb8();
    let (w, h) = img.dimensions();
    let data: Vec<u8> = img.into_raw().iter().map(|v| v.wrapping_add(40)).collect();
    image::save_buffer(path, &data, w, h, image::ColorType::Rgb8).unwrap();
}

#[test]
fn an_image_changed_or_removed_after_loading_is_refused_by_name() {
    let dir = temp_dir("on_demand_changed");
    colmap_dataset(&dir, VIEWS, true);
    // A budget of 0: every use decodes the file again.
    let scene = load(&dir, &options(0)).unwrap();
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_view).collect();
    let mut t = trainer(&scene, 40);
    for _ in 0..3 {
        t.step(&train).unwrap();
    }
    for v in &scene.train {
        repaint(&v.path);
    }
    let before = t.checkpoint_bytes();
    let err = t.step(&train).unwrap_err();
    let TrainError::ViewImage { view, message } = &err else {
        panic!("{err:?}")
    };
    let path = scene.train[*view].path.display().to_string();
    assert!(
        message.contains(&path) && message.contains("changed on disk since the scene was loaded"),
        "{err}"
    );
    assert_eq!(
        t.checkpoint_bytes(),
        before,
        "a refused step leaves the trainer as it was"
    );
    // Removed: the loader's own error, naming the file.
    std::fs::remove_file(&scene.train[0].path).unwrap();
    let err = scene.train[0].image.get().unwrap_err();
    assert!(
        err.to_string().contains(&scene.train[0].path.display().to_string()),
        "{err}"
    );
    // An evaluation names the test view.
    let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_view).collect();
    for v in &scene.test {
        repaint(&v.path);
    }
    let err = t.evaluate(&test).unwrap_err();
    assert!(matches!(err, TrainError::ViewImage { view: 0, .. }), "{err}");
    let mut fresh = trainer(&scene, 40);
    let config = RunConfig {
        eval_every: 0,
        ..RunConfig::default()
    };
    // The run steps on views that no longer decode: the step's error, no checkpoint claimed.
    let err = run(&mut fresh, &train, &test, &config, &StopSignal::new(), |_| {}).unwrap_err();
    assert!(
        matches!(
            &err,
            RunError::Step {
                source: TrainError::ViewImage { .. },
                checkpoint: None
            }
        ),
        "{err}"
    );
}
