//! The forward pass's per-entry spans (which pixels of a tile an entry can reach) come from
//! each billboard's rows computed once per view and cut to the tile; they must be the spans
//! computed for the tile alone, entry by entry, exactly (the renderer's outputs depend on them
//! only through which pixels are tried, but a span cut one column short would drop a hit). The
//! pixel count and column range kept with them (which choose the tile's walk and the texels to
//! prefetch) must be those of the rows.

use bbsplat::billboards::{
    ActivatedBillboards, RandomSceneConfig, TrainedLikeConfig, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::camera::Camera;
use bbsplat::raster::RenderSettings;
use bbsplat::rng::Rng;
use bbsplat::stages::splat_transform::pixel_range;
use bbsplat::strategies::seeded_config;
use bbsplat::testing_internals::raster::entry_spans_both_ways;
use glam::{Vec2, Vec3};
use proptest::prelude::*;

/// Compares the two ways on every tile entry of the view (with `every_billboard`, on every
/// prepared billboard in every tile); returns how many entries had spans narrower than their
/// box and how many boxes missed their tile (so that a test can show both paths were taken).
fn assert_same_spans(scene: &ActivatedBillboards, camera: &Camera, every_billboard: bool) -> (usize, usize) {
    let both = entry_spans_both_ways(&scene.borrowed(), camera, &RenderSettings::default(), every_billboard);
    assert!(!both.is_empty(), "the view lists no entry");
    let (mut narrowed, mut missed) = (0, 0);
    for (e, entry) in both.iter().enumerate() {
        let (fast, reference) = (&entry.fast, &entry.reference);
        assert_eq!(
            fast, reference,
            "entry {e}: spans from the billboard's rows differ from the tile's own"
        );
        let [y0, y1] = reference.0;
        narrowed += usize::from((y0..=y1).any(|y| reference.1[y as usize] != reference.1[y0 as usize]));
        missed += usize::from(!entry.box_meets_tile);
        // The totals kept with the spans, counted from the reference's rows.
        let rows = (y0..=y1).map(|y| reference.1[y as usize]).filter(|[a, b]| a <= b);
        let count: usize = rows.clone().map(|[a, b]| usize::from(b - a) + 1).sum();
        assert_eq!(usize::from(entry.pixels), count, "entry {e}: pixel count");
        let first = rows.clone().map(|[a, _]| a).min();
        let last = rows.map(|[_, b]| b).max();
        match (first, last) {
            (Some(first), Some(last)) => assert_eq!(entry.columns, [first, last], "entry {e}: column range"),
            _ => assert!(
                entry.columns[0] > entry.columns[1],
                "entry {e}: an empty span has an empty column range"
            ),
        }
    }
    (narrowed, missed)
}

#[test]
fn spans_from_billboard_rows_equal_the_per_tile_spans_on_trained_like_scenes() {
    let camera = random_scene_camera(160, 128);
    for config in [
        TrainedLikeConfig::object(3000, 160, 128),
        TrainedLikeConfig::capture(3000, 160, 128),
    ] {
        let (narrowed, missed) = assert_same_spans(&trained_like_scene(&config), &camera, false);
        assert!(narrowed > 100, "only {narrowed} entries were narrowed by their quad");
        assert_eq!(missed, 0, "a binned billboard's box meets its tile");
    }
}

#[test]
fn spans_from_billboard_rows_equal_the_per_tile_spans_on_the_benchmark_scene() {
    let camera = random_scene_camera(128, 128);
    assert_same_spans(
        &random_scene(&RandomSceneConfig::benchmark(8000, 128, 128)),
        &camera,
        false,
    );
}

/// Billboards around and through the camera: crossing the near plane, edge-on, huge (boxes
/// clipped by the image, quads refused for their depth ratio), tiny, and at the image borders.
#[test]
fn spans_from_billboard_rows_equal_the_per_tile_spans_on_hard_geometry() {
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO, Vec3::Y, 90.0, 90.0, 150, 110);
    let mut rng = Rng::new(11);
    let mut scene = ActivatedBillboards::empty(16);
    for _ in 0..1500 {
        scene.positions.push(Vec3::new(
            rng.range(-4.0, 4.0),
            rng.range(-3.0, 3.0),
            rng.range(-3.5, 3.0),
        ));
        scene.quaternions.push([
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ]);
        scene
            .log_scales
            .push(Vec2::new(rng.range(-4.0, 1.5), rng.range(-4.0, 1.5)));
        scene.sh.extend((0..48).map(|_| rng.range(-0.5, 0.5)));
        scene.textures.extend((0..256).map(|_| {
            [
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
            ]
        }));
    }
    let (narrowed, _) = assert_same_spans(&scene, &camera, false);
    assert!(narrowed > 100, "only {narrowed} entries were narrowed by their quad");
    // Every billboard in every tile: the boxes that miss a tile (never listed there by the
    // binning) take the per-entry path, and must give the reference's spans too.
    let (_, missed) = assert_same_spans(&scene, &camera, true);
    assert!(missed > 1000, "only {missed} boxes missed their tile");
}

/// A bound of `pixel_range`: finite, infinite, NaN or huge, with pixel centres on it.
fn bound() -> impl Strategy<Value = f32> {
    prop_oneof![
        -20.0f32..300.0,
        (-20i32..300).prop_map(|i| i as f32 + 0.5),
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(1e30f32),
        Just(-1e30f32),
    ]
}

proptest! {
    #![proptest_config(seeded_config(4096))]

    /// What the cut of a billboard's rows to a tile rests on: for `n₁ ≤ n₂` the columns of
    /// `n₁` pixels are those of `n₂` pixels clamped to `n₁`.
    #[test]
    fn pixel_range_of_fewer_columns_is_the_range_of_more_clamped(
        lo in bound(), hi in bound(), n1 in 0u32..260, extra in 0u32..100,
    ) {
        let (f2, e2) = pixel_range(lo, hi, n1 + extra);
        prop_assert_eq!(pixel_range(lo, hi, n1), (f2.min(n1), e2.min(n1)));
    }
}
