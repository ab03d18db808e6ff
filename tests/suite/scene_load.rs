//! Loading small synthetic datasets: detection, splits, downscaling, compositing, extent.

use crate::scene_support::*;
use bbsplat::scene::colmap::read_model;
use bbsplat::scene::{Background, LoadOptions, SceneFormat, UndistortMode, colmap_binary, colmap_text, load};

fn quiet() -> LoadOptions {
    LoadOptions {
        print_warnings: false,
        ..Default::default()
    }
}

#[test]
fn colmap_binary_and_text_load_the_same_scene() {
    let (b, t) = (temp_dir("load_bin"), temp_dir("load_txt"));
    let m = colmap_dataset(&b, 10, true);
    colmap_dataset(&t, 10, false);
    let sb = load(&b, &quiet()).unwrap();
    let st = load(&t, &quiet()).unwrap();
    assert_eq!(sb.format, SceneFormat::Colmap);
    assert_eq!(sb.source, b.join("sparse/0"));
    for (x, y) in sb.train.iter().zip(&st.train).chain(sb.test.iter().zip(&st.test)) {
        assert_eq!(x.camera, y.camera);
        assert_eq!(x.image, y.image);
    }
    // Every 8th in name order: img_0 and img_8 are held out.
    let test: Vec<&str> = sb.test.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(test, ["img_0.png", "img_8.png"]);
    assert_eq!(sb.train.len(), 8);
    // A PINHOLE view keeps its intrinsics, size and pixels.
    let v0 = &sb.test[0];
    assert_eq!(
        (v0.camera.fx, v0.camera.fy, v0.camera.cx, v0.camera.cy),
        (30.0, 31.0, 16.0, 12.0)
    );
    assert_eq!((v0.camera.width, v0.camera.height), (32, 24));
    assert_eq!(v0.image.get().unwrap().pixel(3, 2), [24, 16, 100]);
    // Pose: X_cam = R X + t, so the world origin is 3 units in front of every camera.
    for v in sb.train.iter().chain(&sb.test) {
        let p = v.camera.world_to_view(glam::Vec3::ZERO);
        assert!((p - glam::Vec3::new(0.0, 0.0, 3.0)).length() < 1e-6);
    }
    // The SIMPLE_RADIAL (k = 0.02 > 0) views are cropped to a few pixels less.
    let v1 = sb.train.iter().find(|v| v.name == "img_1.png").unwrap();
    assert!(v1.camera.width < 32 && v1.camera.width >= 30, "{:?}", v1.camera);
    assert_eq!(v1.camera.fx, 30.0);
    // Points: all three, colours in [0, 1].
    let pts = sb.points.as_ref().unwrap();
    assert_eq!(pts.positions.len(), m.points.len());
    assert_eq!(pts.colours[0], [1.0, 0.0, 0.0]);
}

#[test]
fn extent_ignores_outlier_points() {
    let d = temp_dir("extent");
    colmap_dataset(&d, 10, true);
    let s = load(
        &d,
        &LoadOptions {
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    // Cameras on a circle of radius 3 about the origin, angles 0..2.7 rad.
    let centres: Vec<glam::Vec3> = s.train.iter().map(|v| v.camera.centre()).collect();
    let mean = centres.iter().copied().sum::<glam::Vec3>() / centres.len() as f32;
    let r = centres.iter().map(|c| (*c - mean).length()).fold(0.0, f32::max);
    assert!((s.extent - 1.1 * r).abs() < 1e-5);
    assert!(s.extent < 5.0, "the point at x = 1000 must not matter: {}", s.extent);
}

#[test]
fn text_model_with_comments_and_blank_lines_loads() {
    let d = temp_dir("comments");
    let m = colmap_dataset(&d, 3, false);
    let sparse = d.join("sparse/0");
    let cams = colmap_text::write_cameras(&m.cameras);
    let cams = format!(
        "\n# leading comment\n\n{}\n   \n# trailing comment\n",
        cams.replace('\n', "\n\n")
    );
    std::fs::write(sparse.join("cameras.txt"), cams).unwrap();
    // Images: blank lines between records (not between an image and its keypoints), CRLF, an
    // empty keypoint line, and a missing keypoint line at the end of the file.
    let images = "# header\r\n\r\n100 1 0 0 0 0 0 3 7 img_0.png\r\n16 12 1\r\n\r\n   # indented comment\n\
                  101 1 0 0 0 0 0 3 9 img_1.png\n\n\n102 1 0 0 0 0 0 3 7 img_2.png";
    std::fs::write(sparse.join("images.txt"), images).unwrap();
    let points = format!("# c\n\n{}\n\n", colmap_text::write_points(&m.points));
    std::fs::write(sparse.join("points3D.txt"), points).unwrap();
    let back = read_model(&sparse).unwrap();
    assert_eq!(back.cameras, m.cameras);
    assert_eq!(back.points, m.points);
    assert_eq!(back.images.len(), 3);
    assert_eq!(back.images[0].points2d.len(), 1);
    assert!(back.images[1].points2d.is_empty() && back.images[2].points2d.is_empty());
    assert_eq!(back.images[2].name, "img_2.png");
    let s = load(&d, &quiet()).unwrap();
    assert_eq!(s.train.len() + s.test.len(), 3);
}

#[test]
fn the_model_with_most_images_is_chosen() {
    let d = temp_dir("several");
    colmap_dataset(&d, 3, true);
    let big = model(5);
    std::fs::create_dir_all(d.join("sparse/1")).unwrap();
    colmap_binary::write_model(&big, &d.join("sparse/1")).unwrap();
    for im in &big.images {
        write_png(&d.join("images").join(&im.name), 32, 24);
    }
    let s = load(&d, &quiet()).unwrap();
    assert_eq!(s.source, d.join("sparse/1"));
    assert_eq!(s.train.len() + s.test.len(), 5);
    // The model folder itself can be given.
    let s0 = load(&d.join("sparse/0"), &quiet()).unwrap();
    assert_eq!(s0.train.len() + s0.test.len(), 3);
    assert_eq!(s0.name, s.name);
}

#[test]
fn downscale_and_max_width_scale_intrinsics_exactly() {
    let d = temp_dir("downscale");
    colmap_dataset(&d, 2, true);
    let s = load(
        &d,
        &LoadOptions {
            downscale: 2,
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    let v = s.train.iter().find(|v| v.name == "img_0.png").unwrap();
    assert_eq!((v.camera.width, v.camera.height), (16, 12));
    assert_eq!(
        (v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy),
        (15.0, 15.5, 8.0, 6.0)
    );
    // A 2×2 block average of (8x, 8y, 100): pixel (1, 1) covers x, y ∈ {2, 3} → (20, 20, 100).
    assert_eq!(v.image.get().unwrap().pixel(1, 1), [20, 20, 100]);
    let s = load(
        &d,
        &LoadOptions {
            max_width: Some(12),
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    let v = s.train.iter().find(|v| v.name == "img_0.png").unwrap();
    assert_eq!((v.camera.width, v.camera.height), (12, 9));
    assert_eq!((v.camera.fx, v.camera.cx, v.camera.cy), (11.25, 6.0, 4.5));
    // Shrinking an image under 8 pixels a side is refused (it trained on 1-pixel images).
    for (downscale, max_width, says) in [
        (
            100_000,
            None,
            "32x24 becomes 1x1 with downscale 100000, under the 8 pixels",
        ),
        (1, Some(1), "32x24 becomes 1x1 with downscale 1 and max width 1"),
        (4, None, "becomes 8x6 with downscale 4"),
    ] {
        let options = LoadOptions {
            downscale,
            max_width,
            test_every: 0,
            ..quiet()
        };
        let err = load(&d, &options).unwrap_err().to_string();
        assert!(err.contains(says) && err.contains("img_0.png"), "{err}");
    }
    // A ratio that does not divide: 32 → 11 wide; intrinsics follow the exact size ratio.
    let s = load(
        &d,
        &LoadOptions {
            downscale: 3,
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    let v = s.train.iter().find(|v| v.name == "img_0.png").unwrap();
    assert_eq!((v.camera.width, v.camera.height), (11, 8));
    assert!((v.camera.fx - 30.0 * 11.0 / 32.0).abs() < 1e-5 && (v.camera.cy - 12.0 * 8.0 / 24.0).abs() < 1e-5);
}

fn nerf_synthetic(dir: &std::path::Path, with_test: bool) {
    let train: Vec<String> = (0..4)
        .map(|i| frame(&format!("./train/r_{i}"), 4.0 + i as f64))
        .collect();
    let json = format!(
        r#"{{"camera_angle_x": 0.6911112070083618, "frames": [{}]}}"#,
        train.join(",")
    );
    std::fs::write(dir.join("transforms_train.json"), json).unwrap();
    for i in 0..4 {
        write_rgba_png(&dir.join(format!("train/r_{i}.png")), 20, 10);
    }
    if with_test {
        let json = format!(
            r#"{{"camera_angle_x": 0.6911112070083618, "frames": [{}]}}"#,
            frame("./test/r_0", 5.0)
        );
        std::fs::write(dir.join("transforms_test.json"), json).unwrap();
        write_rgba_png(&dir.join("test/r_0.png"), 20, 10);
    }
}

#[test]
fn nerf_synthetic_composites_alpha_and_uses_the_test_file() {
    let d = temp_dir("synthetic");
    nerf_synthetic(&d, true);
    let white = load(
        &d,
        &LoadOptions {
            background: Background::White,
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!(white.format, SceneFormat::NerfSynthetic);
    assert_eq!((white.train.len(), white.test.len()), (4, 1));
    // File order for NeRF-synthetic.
    assert_eq!(white.train[3].name, "train/r_3");
    let v = &white.train[0];
    let f = 0.5 * 20.0 / (0.5f64 * 0.6911112070083618).tan();
    assert!((v.camera.fx as f64 - f).abs() < 1e-3 && v.camera.fy == v.camera.fx);
    assert_eq!((v.camera.cx, v.camera.cy), (10.0, 5.0));
    // OpenGL c2w → camera at (0, 0, 4) looking down -z: the origin is 4 units ahead.
    assert!((v.camera.world_to_view(glam::Vec3::ZERO) - glam::Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    assert_eq!(v.image.get().unwrap().pixel(0, 0), [255, 0, 0]);
    assert_eq!(v.image.get().unwrap().pixel(19, 0), [255, 255, 255]);
    // 50 % green over white: (127.5, 255, 127.5) → rounded.
    assert_eq!(v.image.get().unwrap().pixel(0, 9), [127, 255, 127]);
    let black = load(&d, &quiet()).unwrap();
    assert_eq!(black.background, Background::Black);
    assert_eq!(black.train[0].image.get().unwrap().pixel(19, 0), [0, 0, 0]);
    assert_eq!(black.train[0].image.get().unwrap().pixel(0, 9), [0, 128, 0]);
    // Without a test file the every-n-th rule applies.
    let d2 = temp_dir("synthetic_no_test");
    nerf_synthetic(&d2, false);
    let s = load(
        &d2,
        &LoadOptions {
            test_every: 2,
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!((s.train.len(), s.test.len()), (2, 2));
}

/// The background of the data: white for NeRF-synthetic images with alpha (composited on
/// white whatever the options say), black for the same dataset without alpha and for COLMAP.
#[test]
fn the_background_comes_from_the_data() {
    use bbsplat::scene::data_background::load_with_data_background;
    let d = temp_dir("data_background");
    nerf_synthetic(&d, true);
    let (s, choice) = load_with_data_background(&d, &quiet()).unwrap();
    assert_eq!(
        (s.background, choice.background),
        (Background::White, Background::White)
    );
    assert!(choice.reason.contains("NeRF-synthetic"), "{}", choice.reason);
    assert_eq!(
        s.train[0].image.get().unwrap().pixel(19, 0),
        [255, 255, 255],
        "composited on white"
    );
    // The same dataset as RGB images: black, and the images are those of any background.
    let rgb = temp_dir("data_background_rgb");
    nerf_synthetic(&rgb, false);
    for i in 0..4 {
        let path = rgb.join(format!("train/r_{i}.png"));
        image::open(&path).unwrap().to_rgb8().save(&path).unwrap();
    }
    let (s, choice) = load_with_data_background(&rgb, &quiet()).unwrap();
    assert_eq!(
        (s.background, choice.background),
        (Background::Black, Background::Black)
    );
    let white = load(
        &rgb,
        &LoadOptions {
            background: Background::White,
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!(s.train[0].image, white.train[0].image);
    // COLMAP: black.
    let c = temp_dir("data_background_colmap");
    colmap_dataset(&c, 6, true);
    let (s, choice) = load_with_data_background(&c, &quiet()).unwrap();
    assert_eq!(
        (s.background, choice.background),
        (Background::Black, Background::Black)
    );
    assert_eq!(Background::from_rgb([1.0; 3]), Some(Background::White));
    assert_eq!(Background::from_rgb([0.0; 3]), Some(Background::Black));
    assert_eq!(Background::from_rgb([0.2, 0.0, 0.0]), None);
}

#[test]
fn transforms_json_per_frame_intrinsics_missing_frames_and_ply() {
    let d = temp_dir("transforms");
    let frames = [
        frame("images/a.png", 4.0),
        // Per-frame intrinsics override the scene's.
        r#"{"file_path": "images/b.png", "fl_x": 40, "cx": 15, "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,5]]}"#
            .to_string(),
        frame("images/missing.png", 6.0),
    ];
    let json = format!(
        r#"{{"fl_x": 30, "fl_y": 31, "cx": 16, "cy": 12, "w": 32, "h": 24, "aabb_scale": 4,
            "ply_file_path": "points.ply", "frames": [{}]}}"#,
        frames.join(",")
    );
    std::fs::write(d.join("transforms.json"), json).unwrap();
    write_png(&d.join("images/a.png"), 32, 24);
    write_png(&d.join("images/b.png"), 32, 24);
    std::fs::write(
        d.join("points.ply"),
        "ply\nformat ascii 1.0\ncomment x\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 255 255\n1 2 3 0 0 0\n",
    )
    .unwrap();
    let s = load(
        &d,
        &LoadOptions {
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!(s.format, SceneFormat::Transforms);
    assert_eq!(s.train.len(), 2);
    assert_eq!(s.warnings.len(), 1);
    let w = &s.warnings[0];
    assert!(
        w.contains("transforms.json") && w.contains("frames[2]") && w.contains("missing.png") && w.contains("skipped"),
        "{w}"
    );
    let b = &s.train[1];
    assert_eq!(
        (b.camera.fx, b.camera.fy, b.camera.cx, b.camera.cy),
        (40.0, 31.0, 15.0, 12.0)
    );
    let pts = s.points.unwrap();
    assert_eq!(pts.positions[1], glam::Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(pts.colours[0], [1.0; 3]);
    // Without the ply file: a warning, no points.
    std::fs::remove_file(d.join("points.ply")).unwrap();
    let s = load(&d.join("transforms.json"), &quiet()).unwrap();
    assert!(s.points.is_none());
    assert!(s.warnings.iter().any(|w| w.contains("points.ply")), "{:?}", s.warnings);
}

#[test]
fn keep_size_mode_keeps_the_colmap_intrinsics() {
    let d = temp_dir("keep_size");
    colmap_dataset(&d, 2, true);
    let s = load(
        &d,
        &LoadOptions {
            undistort: UndistortMode::KeepSize,
            test_every: 0,
            ..quiet()
        },
    )
    .unwrap();
    let v = s.train.iter().find(|v| v.name == "img_1.png").unwrap();
    assert_eq!(
        (v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy),
        (30.0, 30.0, 16.5, 11.5)
    );
    assert_eq!((v.camera.width, v.camera.height), (32, 24));
}

#[test]
fn forcing_a_format() {
    let d = temp_dir("forced");
    colmap_dataset(&d, 2, true);
    nerf_synthetic(&d, true);
    // Detection prefers the JSON files; forcing COLMAP reads the model.
    assert_eq!(load(&d, &quiet()).unwrap().format, SceneFormat::NerfSynthetic);
    let s = load(
        &d,
        &LoadOptions {
            format: Some(SceneFormat::Colmap),
            ..quiet()
        },
    )
    .unwrap();
    assert_eq!(s.format, SceneFormat::Colmap);
    let err = load(
        &d,
        &LoadOptions {
            format: Some(SceneFormat::Transforms),
            ..quiet()
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("transforms.json: cannot access file"), "{err}");
}
