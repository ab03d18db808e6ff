//! The chunked preprocess against the per-billboard one, and the size of its record.

use bbsplat::raster::RenderSettings;
use bbsplat::raster::preprocess::{Prepared, prepare_one, preprocess};
use bbsplat::testing_internals::raster::PREPROCESS_CHUNK;

/// The chunked preprocess with batched SH colours gives [`prepare_one`]'s records bit for
/// bit: several chunks and a partial last chunk, batches with a remainder, culled billboards
/// in between, every SH degree.
#[test]
fn preprocess_equals_prepare_one() {
    use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
    let scene = random_scene(&RandomSceneConfig::benchmark(2 * PREPROCESS_CHUNK + 77, 48, 40));
    let (set, camera) = (scene.borrowed(), random_scene_camera(48, 40));
    for sh_degree in 0..=3 {
        let settings = RenderSettings {
            sh_degree,
            ..RenderSettings::default()
        };
        let want: Vec<Option<Prepared>> = (0..set.len())
            .map(|i| prepare_one(&set, i, &camera, &settings))
            .collect();
        let culled = want.iter().filter(|p| p.is_none()).count();
        assert!(
            culled > 0 && culled < set.len(),
            "the scene should mix culled and kept billboards"
        );
        let bits = |v: &[Option<Prepared>]| format!("{v:?}");
        let got = preprocess(&set, &camera, &settings);
        assert_eq!(bits(&got), bits(&want), "degree {sh_degree}");
    }
}

/// The backward's two flags (`sh_clamped`, `normal_flipped`) live in what was padding, and
/// the `Option` tag in their `bool` niche: the record every per-pixel pass reads is 88 bytes
/// (84 before `plane_offset`).
#[test]
fn prepared_record_stays_88_bytes() {
    assert_eq!(size_of::<Option<Prepared>>(), 88);
}
