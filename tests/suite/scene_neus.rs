//! NeuS/IDR datasets (`cameras_sphere.npz`, `image/`, `mask/`): the conventions checked on the
//! real DTU scan 65 of `../shared/data`, a synthetic round trip from known cameras, masks, and
//! bad input refused with typed errors naming the file.

use bbsplat::camera::Camera;
use bbsplat::scene::npy::{NpyError, write_npy_f64, write_npy_raw, write_npz};
use bbsplat::scene::{LoadOptions, SceneError, SceneFormat, load};
use glam::{DMat4, Vec3};
use std::path::Path;

fn quiet() -> LoadOptions {
    LoadOptions {
        print_warnings: false,
        ..Default::default()
    }
}

#[test]
fn dtu_scan65_cameras_look_at_the_unit_sphere() {
    let Some(dir) = crate::shared_data::shared_data("scene_neus", "dtu_scan65") else {
        return;
    };
    let scene = load(&dir, &quiet()).unwrap();
    assert_eq!(scene.format, SceneFormat::Neus);
    println!(
        "dtu_scan65: view 0 {:?}; warnings {:?}",
        scene.test[0].camera, scene.warnings
    );
    // 49 views, index % 8 == 0 held out: 0, 8, ..., 48.
    assert_eq!((scene.train.len(), scene.test.len()), (42, 7));
    assert_eq!(scene.test[1].name, "000008.png");
    for v in scene.train.iter().chain(&scene.test) {
        let c = &v.camera;
        assert_eq!((c.width, c.height), (400, 300), "{}", v.name);
        // The 1600x1200 intrinsics scaled by 1/4: fx about 2890/4, principal point near the centre.
        assert!(
            c.fx > 600.0 && c.fx < 800.0 && (c.fx - c.fy).abs() < 0.01 * c.fx,
            "{}: {c:?}",
            v.name
        );
        assert!(
            (c.cx - 200.0).abs() < 30.0 && (c.cy - 150.0).abs() < 30.0,
            "{}: {c:?}",
            v.name
        );
        // Outside the unit sphere, looking at its centre: the origin projects near the image
        // centre, and points of the sphere are in front of the camera and inside the image.
        let distance = c.centre().length();
        assert!(distance > 1.5 && distance < 10.0, "{}: centre at {distance}", v.name);
        let (x, y) = c.project(Vec3::ZERO).expect("the origin is in front");
        assert!(
            (x - 200.0).abs() < 80.0 && (y - 150.0).abs() < 60.0,
            "{}: origin at ({x}, {y})",
            v.name
        );
        for p in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            let q = p * 0.5;
            let (qx, qy) = c
                .project(q)
                .unwrap_or_else(|| panic!("{}: {q} behind the camera", v.name));
            assert!(
                (0.0..400.0).contains(&qx) && (0.0..300.0).contains(&qy),
                "{}: {q} at ({qx}, {qy})",
                v.name
            );
        }
        // The object mask: loaded, the object at the image's middle, the corners background,
        // and the image composited on the black background outside it.
        let mask = v.mask.as_ref().expect("mask/ is loaded");
        assert_eq!(mask.len(), 400 * 300);
        let object = mask.iter().filter(|&&m| m >= 128).count();
        assert!(object > 5_000 && object < 100_000, "{}: {object} mask pixels", v.name);
        // The unit sphere, projected (a disc of radius about fx / sqrt(d² - 1) around the
        // origin's image), holds the object: every mask pixel lies inside it.
        let radius = c.fx / (distance * distance - 1.0).sqrt();
        let outside = (0..400 * 300)
            .filter(|&i| mask[i] >= 128)
            .filter(|&i| {
                let (px, py) = ((i % 400) as f32 + 0.5, (i / 400) as f32 + 0.5);
                (px - x).hypot(py - y) > radius * 1.05
            })
            .count();
        assert!(
            outside * 1000 < object,
            "{}: {outside} of {object} mask pixels outside the unit sphere's image",
            v.name
        );
        let (mx, my) = (0..400 * 300)
            .filter(|&i| mask[i] >= 128)
            .fold((0.0, 0.0), |(a, b), i| {
                (
                    a + (i % 400) as f32 / object as f32,
                    b + (i / 400) as f32 / object as f32,
                )
            });
        assert!(
            (mx - x).hypot(my - y) < 0.5 * radius,
            "{}: mask centroid ({mx}, {my}), origin at ({x}, {y})",
            v.name
        );
        assert_eq!(v.image.get().unwrap().pixel(0, 0), [0, 0, 0], "{}", v.name);
    }
    let ignored = load(
        &dir,
        &LoadOptions {
            mask_mode: bbsplat::scene::mask::MaskMode::Ignore,
            ..quiet()
        },
    )
    .unwrap();
    let bright = ignored
        .train
        .iter()
        .filter(|v| v.image.get().unwrap().pixel(0, 0) != [0, 0, 0])
        .count();
    assert!(
        bright > 0,
        "with --mask-mode ignore the photographs keep their background"
    );
    assert!(ignored.train[0].mask.is_some());
}

/// A NeuS dataset in `dir` whose views are `cameras` (at 4× their image size in the archive,
/// scaled by the world-to-sphere `scale`), with grey images of `width × height` and masks.
pub(crate) fn write_neus(dir: &Path, cameras: &[Camera], scale: DMat4, factor: f64) {
    std::fs::create_dir_all(dir.join("image")).unwrap();
    std::fs::create_dir_all(dir.join("mask")).unwrap();
    let mut members = Vec::new();
    for (i, c) in cameras.iter().enumerate() {
        // K in OpenCV's pixel convention at `factor` times the size, [R | t] of the sphere frame.
        let k = DMat4::from_cols_array_2d(&[
            [c.fx as f64 * factor, 0.0, 0.0, 0.0],
            [0.0, c.fy as f64 * factor, 0.0, 0.0],
            [(c.cx as f64) * factor - 0.5, (c.cy as f64) * factor - 0.5, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]);
        let r = c.rotation.as_dmat3();
        let t = c.translation.as_dvec3();
        let rt = DMat4::from_cols(
            r.x_axis.extend(0.0),
            r.y_axis.extend(0.0),
            r.z_axis.extend(0.0),
            t.extend(1.0),
        );
        // world_mat = K·[R|t]·scale⁻¹, times an arbitrary negative scale (P is projective).
        let world = (k * rt * scale.inverse()) * -3.0;
        let rows = |m: DMat4| -> Vec<f64> { m.transpose().to_cols_array().to_vec() };
        members.push((format!("world_mat_{i}.npy"), write_npy_f64(&[4, 4], &rows(world))));
        members.push((format!("scale_mat_{i}.npy"), write_npy_f64(&[4, 4], &rows(scale))));
        let img = image::RgbImage::from_pixel(c.width, c.height, image::Rgb([200, 100, 50]));
        img.save(dir.join(format!("image/{i:06}.png"))).unwrap();
        let mut m = image::GrayImage::new(c.width, c.height);
        for y in 0..c.height {
            for x in 0..c.width / 2 {
                m.put_pixel(x, y, image::Luma([255]));
            }
        }
        m.save(dir.join(format!("mask/{i:03}.png"))).unwrap();
    }
    let refs: Vec<(&str, Vec<u8>)> = members.iter().map(|(n, b)| (n.as_str(), b.clone())).collect();
    std::fs::write(dir.join("cameras_sphere.npz"), write_npz(&refs).unwrap()).unwrap();
}

pub(crate) fn known_cameras() -> Vec<Camera> {
    (0..10)
        .map(|k| {
            let a = k as f32 * 0.6;
            let eye = Vec3::new(3.0 * a.cos(), 0.8 + 0.1 * k as f32, 3.0 * a.sin());
            let mut c = Camera::look_at(eye, Vec3::new(0.1, 0.0, -0.1), Vec3::Y, 70.0, 72.0, 64, 48);
            c.cx = 31.0;
            c.cy = 25.0;
            c
        })
        .collect()
}

#[test]
fn synthetic_round_trip_recovers_the_cameras() {
    let dir = tempfile_dir("neus_round_trip");
    let cams = known_cameras();
    let scale = DMat4::from_cols_array_2d(&[
        [250.0, 0.0, 0.0, 0.0],
        [0.0, 250.0, 0.0, 0.0],
        [0.0, 0.0, 250.0, 0.0],
        [10.0, -20.0, 600.0, 1.0],
    ]);
    write_neus(&dir, &cams, scale, 4.0);
    let scene = load(&dir, &quiet()).unwrap();
    assert_eq!(scene.format, SceneFormat::Neus);
    assert_eq!((scene.train.len(), scene.test.len()), (8, 2));
    let mut views: Vec<_> = scene.train.iter().chain(&scene.test).collect();
    views.sort_by(|a, b| a.name.cmp(&b.name));
    for (v, c) in views.iter().zip(&cams) {
        let got = &v.camera;
        for (a, b) in [(got.fx, c.fx), (got.fy, c.fy), (got.cx, c.cx), (got.cy, c.cy)] {
            assert!((a - b).abs() < 1e-3, "{}: {got:?} against {c:?}", v.name);
        }
        assert!(
            (got.rotation - c.rotation)
                .to_cols_array()
                .iter()
                .fold(0.0f32, |m, v| m.max(v.abs()))
                < 1e-5,
            "{}",
            v.name
        );
        assert!(
            (got.translation - c.translation).abs().max_element() < 1e-4,
            "{}",
            v.name
        );
        let mask = v.mask.as_ref().unwrap();
        assert_eq!((mask[0], mask[63]), (255, 0));
        // Composited on black outside the mask.
        assert_eq!(
            (v.image.get().unwrap().pixel(0, 0), v.image.get().unwrap().pixel(63, 0)),
            ([200, 100, 50], [0, 0, 0])
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn tempfile_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Whether an npy problem is the expected one.
type ProblemCheck = fn(&NpyError) -> bool;

#[test]
fn bad_archives_are_refused_naming_the_file_and_array() {
    let dir = tempfile_dir("neus_bad");
    let cams = known_cameras();
    write_neus(&dir, &cams[..2], DMat4::IDENTITY, 1.0);
    let npz = dir.join("cameras_sphere.npz");
    let good = std::fs::read(&npz).unwrap();
    let with = |members: Vec<(&str, Vec<u8>)>| {
        std::fs::write(&npz, write_npz(&members).unwrap()).unwrap();
        load(&dir, &quiet()).unwrap_err()
    };
    let eye = write_npy_f64(&[4, 4], &DMat4::IDENTITY.to_cols_array());
    // A missing scale_mat.
    let e = with(vec![("world_mat_0.npy", eye.clone()), ("world_mat_1.npy", eye.clone())]);
    assert!(matches!(e, SceneError::Parse { .. }), "{e}");
    assert!(
        e.to_string().contains("cameras_sphere.npz") && e.to_string().contains("scale_mat_0"),
        "{e}"
    );
    // A big-endian, a Fortran-order, a wrong-shape, a truncated and an integer array.
    let cases: Vec<(Vec<u8>, ProblemCheck)> = vec![
        (write_npy_raw(">f8", &[4, 4], &[0; 128]), |p| {
            matches!(p, NpyError::BigEndian(_))
        }),
        (
            {
                let mut b = write_npy_raw("<f8", &[4, 4], &[0; 128]);
                let at = b.windows(5).position(|w| w == b"False").unwrap();
                b.splice(at..at + 5, *b"True ");
                b
            },
            |p| matches!(p, NpyError::FortranOrder),
        ),
        (write_npy_f64(&[2, 4], &[0.0; 8]), |p| {
            matches!(p, NpyError::Shape { .. })
        }),
        (write_npy_raw("<f8", &[4, 4], &[0; 100]), |p| {
            matches!(p, NpyError::Truncated { .. })
        }),
        (write_npy_raw("<i8", &[4, 4], &[0; 128]), |p| {
            matches!(p, NpyError::UnsupportedDtype(_))
        }),
        (b"\x93NUMPZ\x01\x00".to_vec(), |p| matches!(p, NpyError::BadMagic)),
    ];
    for (bytes, want) in cases {
        let e = with(vec![
            ("world_mat_0.npy", bytes),
            ("scale_mat_0.npy", eye.clone()),
            ("world_mat_1.npy", eye.clone()),
            ("scale_mat_1.npy", eye.clone()),
        ]);
        match &e {
            SceneError::Npy { file, array, problem } => {
                assert_eq!(file, &npz);
                assert_eq!(array.as_deref(), Some("world_mat_0"));
                assert!(want(problem), "{e}");
            }
            other => panic!("expected an npy error, got {other}"),
        }
        assert!(
            e.to_string().contains("cameras_sphere.npz") && e.to_string().contains("world_mat_0"),
            "{e}"
        );
    }
    // A singular projection.
    let e = with(vec![
        ("world_mat_0.npy", write_npy_f64(&[4, 4], &[0.0; 16])),
        ("scale_mat_0.npy", eye.clone()),
        ("world_mat_1.npy", eye.clone()),
        ("scale_mat_1.npy", eye.clone()),
    ]);
    assert!(e.to_string().contains("singular"), "{e}");
    // Not a zip.
    std::fs::write(&npz, b"not a zip").unwrap();
    let e = load(&dir, &quiet()).unwrap_err();
    assert!(
        matches!(
            e,
            SceneError::Npy {
                problem: NpyError::Zip(_),
                ..
            }
        ),
        "{e}"
    );
    // A missing mask, then a mask of the wrong size, each named.
    std::fs::write(&npz, &good).unwrap();
    std::fs::remove_file(dir.join("mask/001.png")).unwrap();
    let e = load(&dir, &quiet()).unwrap_err();
    assert!(matches!(e, SceneError::MissingMask { .. }), "{e}");
    assert!(e.to_string().contains("000001.png"), "{e}");
    image::GrayImage::new(5, 5).save(dir.join("mask/001.png")).unwrap();
    let e = load(&dir, &quiet()).unwrap_err();
    assert!(matches!(e, SceneError::ImageSize { .. }), "{e}");
    assert!(e.to_string().contains("001.png"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn masks_dir_applies_to_any_format_matched_by_stem() {
    let dir = tempfile_dir("neus_masks_dir");
    let cams = known_cameras();
    write_neus(&dir, &cams[..3], DMat4::IDENTITY, 2.0);
    // A separate mask folder keeping the right half instead, named by the images' stems.
    let other = dir.join("my_masks");
    std::fs::create_dir_all(&other).unwrap();
    for i in 0..3 {
        let mut m = image::GrayImage::new(64, 48);
        for y in 0..48 {
            for x in 32..64 {
                m.put_pixel(x, y, image::Luma([255]));
            }
        }
        m.save(other.join(format!("{i:06}.png"))).unwrap();
    }
    let options = LoadOptions {
        masks_dir: Some(other.clone()),
        test_every: 0,
        ..quiet()
    };
    let scene = load(&dir, &options).unwrap();
    for v in &scene.train {
        assert_eq!(v.image.get().unwrap().pixel(0, 0), [0, 0, 0]);
        assert_eq!(v.image.get().unwrap().pixel(63, 0), [200, 100, 50]);
    }
    std::fs::remove_file(other.join("000002.png")).unwrap();
    let e = load(&dir, &options).unwrap_err();
    assert!(matches!(e, SceneError::MissingMask { .. }), "{e}");
    assert!(
        e.to_string().contains("000002.png") && e.to_string().contains("my_masks"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
