//! LLFF datasets (`poses_bounds.npy`, `images_N/`): the conventions checked on the real fern of
//! `../shared/data`, a synthetic round trip from known cameras, the folder rule, and bad input
//! refused with typed errors naming the file.

use bbsplat::camera::Camera;
use bbsplat::scene::npy::{NpyError, write_npy_f64, write_npy_raw};
use bbsplat::scene::{LoadOptions, SceneError, SceneFormat, load};
use glam::Vec3;
use std::path::{Path, PathBuf};

fn quiet() -> LoadOptions {
    LoadOptions {
        print_warnings: false,
        ..Default::default()
    }
}

#[test]
fn fern_cameras_face_forward_and_see_the_bounded_points() {
    let Some(dir) = crate::shared_data::shared_data("scene_llff", "fern_llff") else {
        return;
    };
    let scene = load(&dir, &quiet()).unwrap();
    assert_eq!(scene.format, SceneFormat::Llff);
    // 20 images, 0, 8 and 16 held out.
    assert_eq!((scene.train.len(), scene.test.len()), (17, 3));
    assert_eq!(scene.test[1].name, "image008.png");
    let views: Vec<_> = scene.train.iter().chain(&scene.test).collect();
    // hwf says 3024 x 4032 with a focal of about 3260 px: 1/8 of it at 504 x 378.
    for v in &views {
        let c = &v.camera;
        assert_eq!((c.width, c.height), (504, 378));
        assert!(c.fx > 350.0 && c.fx < 470.0 && c.fx == c.fy, "{}: {c:?}", v.name);
        assert_eq!((c.cx, c.cy), (252.0, 189.0));
    }
    // Forward-facing: every camera looks within 20 degrees of the mean look direction, and
    // the centres spread much less than the depth bounds.
    let look = |c: &Camera| c.rotation.row(2);
    let mean = views.iter().map(|v| look(&v.camera)).sum::<Vec3>().normalize();
    for v in &views {
        let angle = look(&v.camera).dot(mean).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(angle < 20.0, "{}: {angle} degrees off the mean look direction", v.name);
    }
    // The initial points (between the depth bounds) are in front of every camera and most of
    // them project inside most images: the views see one scene in front of them.
    let points = scene.points.as_ref().expect("LLFF gets points from its depth bounds");
    assert_eq!(points.positions.len(), 17 * 2_000);
    let sample: Vec<Vec3> = points.positions.iter().step_by(97).copied().collect();
    for v in &views {
        let inside = sample
            .iter()
            .filter(|p| {
                v.camera
                    .project(**p)
                    .is_some_and(|(x, y)| (0.0..504.0).contains(&x) && (0.0..378.0).contains(&y))
            })
            .count();
        assert!(
            inside * 2 > sample.len(),
            "{}: {inside} of {} points in the image",
            v.name,
            sample.len()
        );
    }
    // The point colours are the images' (not a grey placeholder).
    let spread = points
        .colours
        .iter()
        .map(|c| c[1])
        .fold((1.0f32, 0.0f32), |(a, b), g| (a.min(g), b.max(g)));
    assert!(spread.1 - spread.0 > 0.3, "colours {spread:?}");
}

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The `poses_bounds.npy` row of `c` (full size `factor` times the camera's) with bounds.
fn row_of(c: &Camera, factor: f64, bounds: [f64; 2]) -> Vec<f64> {
    let r = c.rotation.as_dmat3();
    let (right, down, forward) = (r.row(0), r.row(1), r.row(2));
    let back = -forward;
    let centre = c.centre_f64();
    let (h, w) = (c.height as f64 * factor, c.width as f64 * factor);
    let mut row = Vec::new();
    for k in 0..3 {
        row.extend([down[k], right[k], back[k], centre[k], [h, w, c.fx as f64 * factor][k]]);
    }
    row.extend(bounds);
    row
}

fn write_llff(dir: &Path, cams: &[Camera], folder: &str, factor: f64) {
    let data: Vec<f64> = cams.iter().flat_map(|c| row_of(c, factor, [1.0, 20.0])).collect();
    std::fs::write(dir.join("poses_bounds.npy"), write_npy_f64(&[cams.len(), 17], &data)).unwrap();
    std::fs::create_dir_all(dir.join(folder)).unwrap();
    for (i, c) in cams.iter().enumerate() {
        image::RgbImage::from_pixel(c.width, c.height, image::Rgb([10, 20, 30]))
            .save(dir.join(format!("{folder}/IMG_{i:04}.JPG.png")))
            .unwrap();
    }
}

fn known_cameras() -> Vec<Camera> {
    (0..9)
        .map(|k| {
            let eye = Vec3::new(0.2 * k as f32 - 0.8, 0.1 * (k % 3) as f32, 0.0);
            Camera::look_at(eye, Vec3::new(0.0, 0.0, 8.0), -Vec3::Y, 50.0, 50.0, 80, 60)
        })
        .collect()
}

#[test]
fn synthetic_round_trip_recovers_the_cameras() {
    let dir = tempdir("llff_round_trip");
    let cams = known_cameras();
    write_llff(&dir, &cams, "images_4", 4.0);
    let scene = load(&dir, &quiet()).unwrap();
    assert_eq!(scene.format, SceneFormat::Llff);
    assert_eq!((scene.train.len(), scene.test.len()), (7, 2));
    let mut views: Vec<_> = scene.train.iter().chain(&scene.test).collect();
    views.sort_by(|a, b| a.name.cmp(&b.name));
    for (v, c) in views.iter().zip(&cams) {
        let got = &v.camera;
        assert_eq!((got.fx, got.fy, got.cx, got.cy), (50.0, 50.0, 40.0, 30.0), "{}", v.name);
        assert!(
            (got.rotation - c.rotation)
                .to_cols_array()
                .iter()
                .fold(0.0f32, |m, v| m.max(v.abs()))
                < 1e-6,
            "{}",
            v.name
        );
        assert!(
            (got.translation - c.translation).abs().max_element() < 1e-6,
            "{}",
            v.name
        );
    }
    // Points in front of every camera between the bounds.
    for p in &scene.points.as_ref().unwrap().positions {
        for c in &cams {
            let z = c.world_to_view(*p).z;
            assert!(z > 0.5 && z < 25.0, "depth {z}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_largest_matching_folder_is_chosen_unless_downscale_names_one() {
    let dir = tempdir("llff_folders");
    let cams = known_cameras();
    write_llff(&dir, &cams, "images_8", 8.0);
    let half: Vec<Camera> = cams
        .iter()
        .map(|c| Camera {
            fx: c.fx * 2.0,
            fy: c.fy * 2.0,
            cx: c.cx * 2.0,
            cy: c.cy * 2.0,
            width: c.width * 2,
            height: c.height * 2,
            ..*c
        })
        .collect();
    write_llff(&dir, &half, "images_4", 4.0);
    // A folder with too few images is passed over.
    std::fs::create_dir_all(dir.join("images_2")).unwrap();
    image::RgbImage::new(320, 240).save(dir.join("images_2/a.png")).unwrap();
    let scene = load(&dir, &quiet()).unwrap();
    assert_eq!(scene.train[0].camera.width, 160);
    assert!(scene.train[0].path.starts_with(dir.join("images_4")));
    let scene = load(
        &dir,
        &LoadOptions {
            downscale: 8,
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!((scene.train[0].camera.width, scene.train[0].camera.fx), (80, 50.0));
    assert!(scene.train[0].path.starts_with(dir.join("images_8")));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_pose_files_are_refused_naming_the_file() {
    let dir = tempdir("llff_bad");
    let cams = known_cameras();
    write_llff(&dir, &cams, "images_4", 4.0);
    let file = dir.join("poses_bounds.npy");
    let good: Vec<f64> = cams.iter().flat_map(|c| row_of(c, 4.0, [1.0, 20.0])).collect();
    let with = |bytes: Vec<u8>| {
        std::fs::write(&file, bytes).unwrap();
        load(&dir, &quiet()).unwrap_err()
    };
    let npy = |e: &SceneError| match e {
        SceneError::Npy { file: f, problem, .. } => {
            assert_eq!(f, &file);
            problem.clone()
        }
        other => panic!("expected an npy error, got {other}"),
    };
    let e = with(write_npy_f64(&[9, 15], &good[..135]));
    assert!(matches!(npy(&e), NpyError::Shape { .. }), "{e}");
    assert!(
        e.to_string().contains("poses_bounds.npy") && e.to_string().contains("(N, 17)"),
        "{e}"
    );
    let body: Vec<u8> = good.iter().flat_map(|v| v.to_be_bytes()).collect();
    let e = with(write_npy_raw(">f8", &[9, 17], &body));
    assert!(matches!(npy(&e), NpyError::BigEndian(_)), "{e}");
    let e = with(write_npy_raw("<f8", &[9, 17], &body[..body.len() - 8]));
    assert!(matches!(npy(&e), NpyError::Truncated { .. }), "{e}");
    let mut longer = body.clone();
    longer.extend([0; 8]);
    let e = with(write_npy_raw("<f8", &[9, 17], &longer));
    assert!(matches!(npy(&e), NpyError::SizeMismatch { .. }), "{e}");
    // float32 is read too.
    let f4: Vec<u8> = good.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
    std::fs::write(&file, write_npy_raw("<f4", &[9, 17], &f4)).unwrap();
    assert_eq!(load(&dir, &quiet()).unwrap().train.len(), 7);
    // Bad values, named by row.
    let mut bounds = good.clone();
    bounds[17 * 3 + 15] = 30.0;
    let e = with(write_npy_f64(&[9, 17], &bounds));
    assert!(
        matches!(e, SceneError::Parse { .. }) && e.to_string().contains("row 3"),
        "{e}"
    );
    let mut skewed = good.clone();
    skewed[17 * 5] = 2.0;
    let e = with(write_npy_f64(&[9, 17], &skewed));
    assert!(
        e.to_string().contains("row 5") && e.to_string().contains("not a rotation"),
        "{e}"
    );
    let mut nan = good.clone();
    nan[17 * 2 + 3] = f64::NAN;
    let e = with(write_npy_f64(&[9, 17], &nan));
    assert!(
        e.to_string().contains("row 2") && e.to_string().contains("not finite"),
        "{e}"
    );
    // Another aspect ratio than hwf's.
    let mut tall = good.clone();
    for r in 0..9 {
        tall[17 * r + 4] *= 2.0;
    }
    let e = with(write_npy_f64(&[9, 17], &tall));
    assert!(e.to_string().contains("aspect ratio"), "{e}");
    // One pose too many for the images.
    let mut more = good.clone();
    more.extend_from_slice(&good[..17]);
    let e = with(write_npy_f64(&[10, 17], &more));
    assert!(e.to_string().contains("10 images"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
