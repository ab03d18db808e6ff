//! Write-then-read round trips of COLMAP models, binary and text: exactly the same model.

use bbsplat::scene::colmap::{
    CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint3D, Point2D, TrackElement, read_model,
};
use bbsplat::scene::{colmap_binary as bin, colmap_text as txt};
use bbsplat::strategies::seeded_config;
use proptest::prelude::*;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Any finite f64, all magnitudes and both signs.
fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO | prop::num::f64::NEGATIVE,
        -10.0f64..10.0,
    ]
    .prop_filter("finite", |v| v.is_finite())
}

fn camera() -> impl Strategy<Value = ColmapCamera> {
    (
        any::<u32>(),
        prop::sample::select(CameraModel::ALL.to_vec()),
        1u64..=u32::MAX as u64,
        1u64..=u32::MAX as u64,
        prop::collection::vec(finite(), 8),
        (
            1e-3f64..1e6,
            prop::num::f64::POSITIVE.prop_filter("finite", |v| v.is_finite() && *v > 0.0),
        ),
    )
        .prop_map(|(id, model, width, height, mut params, (f0, f1))| {
            params.truncate(model.num_params());
            // Focal lengths must be positive.
            params[0] = f0;
            if matches!(model, CameraModel::Pinhole | CameraModel::Opencv) {
                params[1] = f1;
            }
            ColmapCamera {
                id,
                model,
                width,
                height,
                params,
            }
        })
}

fn image(camera_ids: Vec<u32>) -> impl Strategy<Value = ColmapImage> {
    let qvec = prop::array::uniform4(-1e3f64..1e3)
        .prop_filter("quaternion too short", |q| q.iter().map(|v| v * v).sum::<f64>() > 1e-6);
    (
        any::<u32>(),
        qvec,
        prop::array::uniform3(finite()),
        prop::sample::select(camera_ids),
        "[A-Za-z0-9_éλ-][A-Za-z0-9_./ éλ-]{0,15}[A-Za-z0-9éλ]",
        prop::collection::vec(
            (prop::array::uniform2(finite()), prop_oneof![Just(-1i64), any::<i64>()]),
            0..6,
        ),
    )
        .prop_map(|(id, qvec, tvec, camera_id, name, pts)| ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d: pts
                .into_iter()
                .map(|(xy, point3d_id)| Point2D { xy, point3d_id })
                .collect(),
        })
}

fn point() -> impl Strategy<Value = ColmapPoint3D> {
    (
        any::<u64>(),
        prop::array::uniform3(finite()),
        any::<[u8; 3]>(),
        finite(),
        prop::collection::vec(any::<(u32, u32)>(), 0..5),
    )
        .prop_map(|(id, xyz, rgb, error, track)| ColmapPoint3D {
            id,
            xyz,
            rgb,
            error,
            track: track
                .into_iter()
                .map(|(image_id, point2d_idx)| TrackElement { image_id, point2d_idx })
                .collect(),
        })
}

/// Keeps the first record of each id.
fn unique_by<T, K: std::hash::Hash + Eq>(v: Vec<T>, key: impl Fn(&T) -> K) -> Vec<T> {
    let mut seen = HashSet::new();
    v.into_iter().filter(|x| seen.insert(key(x))).collect()
}

fn model() -> impl Strategy<Value = ColmapModel> {
    prop::collection::vec(camera(), 1..5)
        .prop_map(|c| unique_by(c, |c| c.id))
        .prop_flat_map(|cameras| {
            let ids: Vec<u32> = cameras.iter().map(|c| c.id).collect();
            (
                Just(cameras),
                prop::collection::vec(image(ids), 0..5).prop_map(|v| unique_by(v, |i| i.id)),
                prop::collection::vec(point(), 0..6).prop_map(|v| unique_by(v, |p| p.id)),
            )
        })
        .prop_map(|(cameras, images, points)| ColmapModel {
            cameras,
            images,
            points,
        })
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("scene_roundtrip_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

proptest! {
    #![proptest_config(seeded_config(256))]

    #[test]
    fn binary_round_trip_is_exact(m in model()) {
        let f = Path::new("x.bin");
        prop_assert_eq!(bin::parse_cameras(&bin::write_cameras(&m.cameras), f).unwrap(), m.cameras.clone());
        prop_assert_eq!(bin::parse_images(&bin::write_images(&m.images), f).unwrap(), m.images.clone());
        prop_assert_eq!(bin::parse_points(&bin::write_points(&m.points), f).unwrap(), m.points.clone());
    }

    #[test]
    fn text_round_trip_is_exact(m in model()) {
        let f = Path::new("x.txt");
        prop_assert_eq!(txt::parse_cameras(&txt::write_cameras(&m.cameras), f).unwrap(), m.cameras.clone());
        prop_assert_eq!(txt::parse_images(&txt::write_images(&m.images).unwrap(), f).unwrap(), m.images.clone());
        prop_assert_eq!(txt::parse_points(&txt::write_points(&m.points), f).unwrap(), m.points.clone());
    }
}

proptest! {
    #![proptest_config(seeded_config(32))]

    /// Through files and `read_model` (which also cross-checks camera references).
    #[test]
    fn model_files_round_trip(m in model()) {
        let dir = temp_dir("files");
        let (b, t) = (dir.join("bin"), dir.join("txt"));
        std::fs::create_dir_all(&b).unwrap();
        std::fs::create_dir_all(&t).unwrap();
        bin::write_model(&m, &b).unwrap();
        txt::write_model(&m, &t).unwrap();
        prop_assert_eq!(read_model(&b).unwrap(), m.clone());
        prop_assert_eq!(read_model(&t).unwrap(), m);
    }
}

#[test]
fn extreme_values_round_trip() {
    let m = ColmapModel {
        cameras: vec![ColmapCamera {
            id: u32::MAX,
            model: CameraModel::Opencv,
            width: u32::MAX as u64,
            height: 1,
            params: vec![f64::MIN_POSITIVE, f64::MAX, -0.0, f64::MIN, 5e-324, -5e-324, 1e308, 0.1],
        }],
        images: vec![ColmapImage {
            id: 0,
            qvec: [1.0, 0.0, -0.0, 1e-300],
            tvec: [f64::MAX, f64::MIN, 5e-324],
            camera_id: u32::MAX,
            name: "dir with space/ünï cødé.JPG".into(),
            points2d: vec![
                Point2D {
                    xy: [0.0, -0.0],
                    point3d_id: -1,
                },
                Point2D {
                    xy: [1e300, -1e-300],
                    point3d_id: i64::MAX,
                },
                Point2D {
                    xy: [0.5, 0.5],
                    point3d_id: i64::MIN,
                },
            ],
        }],
        points: vec![ColmapPoint3D {
            id: u64::MAX,
            xyz: [0.0, f64::MAX, -5e-324],
            rgb: [0, 128, 255],
            error: -1.0,
            track: vec![TrackElement {
                image_id: u32::MAX,
                point2d_idx: 0,
            }],
        }],
    };
    let f = Path::new("x");
    assert_eq!(bin::parse_images(&bin::write_images(&m.images), f).unwrap(), m.images);
    assert_eq!(
        txt::parse_images(&txt::write_images(&m.images).unwrap(), f).unwrap(),
        m.images
    );
    assert_eq!(
        bin::parse_cameras(&bin::write_cameras(&m.cameras), f).unwrap(),
        m.cameras
    );
    assert_eq!(
        txt::parse_cameras(&txt::write_cameras(&m.cameras), f).unwrap(),
        m.cameras
    );
    assert_eq!(bin::parse_points(&bin::write_points(&m.points), f).unwrap(), m.points);
    assert_eq!(txt::parse_points(&txt::write_points(&m.points), f).unwrap(), m.points);
    // -0.0 survives bit-exactly.
    let back = txt::parse_cameras(&txt::write_cameras(&m.cameras), f).unwrap();
    assert!(back[0].params[2].is_sign_negative());
}

/// The real beer model survives binary → text → binary byte for byte.
#[test]
fn real_model_binary_text_binary() {
    let Some(dir) = crate::shared_data::shared_data("real_model_binary_text_binary", "beer_colmap/sparse/0") else {
        return;
    };
    let m = read_model(&dir).unwrap();
    let t = temp_dir("beer");
    txt::write_model(&m, &t).unwrap();
    let back = read_model(&t).unwrap();
    assert_eq!(back, m);
    for (name, bytes) in [
        ("cameras.bin", bin::write_cameras(&back.cameras)),
        ("images.bin", bin::write_images(&back.images)),
        ("points3D.bin", bin::write_points(&back.points)),
    ] {
        assert_eq!(bytes, std::fs::read(dir.join(name)).unwrap(), "{name}");
    }
}
