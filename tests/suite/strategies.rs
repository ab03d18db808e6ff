//! The proptest strategies: billboards in front of the camera, texture coordinates off texel borders.

use bbsplat::strategies::{billboard_in_front, camera, uv_off_texel_borders};
use proptest::strategy::Strategy;
use proptest::strategy::ValueTree;
use proptest::test_runner::TestRunner;

#[test]
fn billboards_are_in_front_and_on_screen() {
    let mut runner = TestRunner::deterministic();
    for _ in 0..64 {
        let cam = camera().new_tree(&mut runner).unwrap().current();
        let b = billboard_in_front(cam).new_tree(&mut runner).unwrap().current();
        let v = cam.world_to_view(b.position);
        assert!(v.z >= 1.99 && v.z <= 6.01, "{v}");
        let (x, y) = cam.project(b.position).unwrap();
        assert!(x > 0.0 && x < cam.width as f32 && y > 0.0 && y < cam.height as f32);
    }
}

#[test]
fn uv_stays_off_borders() {
    let mut runner = TestRunner::deterministic();
    for _ in 0..256 {
        let uv = uv_off_texel_borders(16, 0.05).new_tree(&mut runner).unwrap().current();
        for c in [uv.x, uv.y] {
            let t = (c + 1.0) * 0.5 * 15.0;
            let frac = t - t.floor();
            assert!((0.049..=0.951).contains(&frac), "{c} -> {t}");
            assert!((-1.0..=1.0).contains(&c));
        }
    }
}
