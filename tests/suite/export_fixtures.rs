//! Small seeded scenes and cameras shared by the export tests of the suite (`export.rs`) and the
//! glTF read-back test crate (`tests/gltf_readback.rs`), which includes this file by path.

use bbsplat::ActivatedBillboards;
use bbsplat::billboards::{RandomSceneConfig, random_scene, random_scene_camera};
use bbsplat::camera::Camera;
use glam::Vec3;

/// `n` random billboards with `ts`×`ts` textures in front of [`random_scene_camera`] (64×48).
pub fn scene(n: usize, ts: usize, seed: u64) -> ActivatedBillboards {
    random_scene(&RandomSceneConfig {
        billboards: n,
        width: 64,
        height: 48,
        texture_size: ts,
        footprint_px: 12.0,
        alpha_range: (0.05, 0.95),
        seed,
    })
}

/// Two cameras of the same 64×48 size: the random scene's camera and one looking from the side.
pub fn test_cameras() -> Vec<Camera> {
    vec![
        random_scene_camera(64, 48),
        Camera::look_at(
            Vec3::new(3.0, -1.0, 0.5),
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::new(0.0, -1.0, 0.0),
            60.0,
            70.0,
            64,
            48,
        ),
    ]
}
