//! Lens distortion: the iterative inverse, the undistorted rectangle, and a straight-line check
//! with the fox scene's stated model.

use bbsplat::scene::colmap::Intrinsics;
use bbsplat::scene::distortion::Distortion;
use bbsplat::scene::undistort::{UndistortMode, plan};
use bbsplat::scene::{LoadOptions, SceneFormat, load};
use bbsplat::strategies::seeded_config;
use proptest::prelude::*;
use std::path::{Path, PathBuf};

/// A camera of 64-1000 × 64-1000 pixels with a realistic distortion that is invertible over the
/// whole image: the radial profile r·(1 + k1 r² + k2 r⁴ + k3 r⁶) has slope ≥ 0.3 up to 1.5×
/// the image corner radius.
fn camera() -> impl Strategy<Value = (Intrinsics, u32, u32)> {
    (
        64u32..1000,
        64u32..1000,
        0.6f64..2.0,
        0.9f64..1.1,
        0.35f64..0.65,
        0.35f64..0.65,
        (
            -0.4f64..0.4,
            -0.2f64..0.2,
            -0.05f64..0.05,
            -0.01f64..0.01,
            -0.01f64..0.01,
        ),
    )
        .prop_map(|(w, h, f_rel, aspect, cx_rel, cy_rel, (k1, k2, k3, p1, p2))| {
            let fx = f_rel * w.max(h) as f64;
            let k = Intrinsics {
                fx,
                fy: fx * aspect,
                cx: cx_rel * w as f64,
                cy: cy_rel * h as f64,
                distortion: Distortion { k1, k2, k3, p1, p2 },
            };
            (k, w, h)
        })
        .prop_filter("distortion not invertible over the image", |(k, w, h)| {
            let corners = [(0.0, 0.0), (*w as f64, 0.0), (0.0, *h as f64), (*w as f64, *h as f64)];
            let r_max = corners
                .iter()
                .map(|&(x, y)| ((x - k.cx) / k.fx).hypot((y - k.cy) / k.fy))
                .fold(0.0, f64::max);
            let d = k.distortion;
            (0..=100).all(|i| {
                let r2 = (1.5 * r_max * i as f64 / 100.0).powi(2);
                1.0 + 3.0 * d.k1 * r2 + 5.0 * d.k2 * r2 * r2 + 7.0 * d.k3 * r2 * r2 * r2 >= 0.3
            })
        })
}

proptest! {
    #![proptest_config(seeded_config(256))]

    /// distort(undistort(p)) = p within 1e-4 px, for pixels anywhere in the image.
    #[test]
    fn undistort_inverts_distort_across_the_image(
        (k, w, h) in camera(),
        pts in prop::collection::vec((0.0f64..=1.0, 0.0f64..=1.0), 32),
    ) {
        let d = k.distortion;
        for (a, b) in pts {
            let (px, py) = (a * w as f64, b * h as f64);
            let pd = [(px - k.cx) / k.fx, (py - k.cy) / k.fy];
            let p = d.undistort(pd);
            prop_assert!(p.is_some(), "no inverse at ({px}, {py}) for {k:?}");
            let q = d.distort(p.unwrap());
            let err = (k.fx * (q[0] - pd[0])).hypot(k.fy * (q[1] - pd[1]));
            prop_assert!(err < 1e-4, "{err} px at ({px}, {py})");
        }
    }

    /// undistort(distort(q)) = q for undistorted points whose image is inside the picture.
    #[test]
    fn distort_then_undistort_is_identity(
        (k, w, h) in camera(),
        pts in prop::collection::vec((0.05f64..=0.95, 0.05f64..=0.95), 32),
    ) {
        let d = k.distortion;
        for (a, b) in pts {
            let q = [(a * w as f64 - k.cx) / k.fx, (b * h as f64 - k.cy) / k.fy];
            let p = d.undistort(d.distort(q)).unwrap();
            prop_assert!((k.fx * (p[0] - q[0])).hypot(k.fy * (p[1] - q[1])) < 1e-4);
        }
    }

    /// The cropped rectangle is covered by the source everywhere, and is maximal: one pixel
    /// more on any side would leave it (unless limited by the 2× rule).
    #[test]
    fn crop_rectangle_is_covered_and_tight((k, w, h) in camera()) {
        let p = plan(&k, w, h, UndistortMode::Crop).unwrap();
        let (fw, fh) = (w as f64, h as f64);
        let inside = |q: [f64; 2]| q[0] >= -0.011 && q[0] <= fw + 0.011 && q[1] >= -0.011 && q[1] <= fh + 0.011;
        let n = 200;
        let mut worst_out = [0.0f64; 4];
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let border = [
                [0.0, t * p.height as f64],
                [p.width as f64, t * p.height as f64],
                [t * p.width as f64, 0.0],
                [t * p.width as f64, p.height as f64],
            ];
            for (side, b) in border.iter().enumerate() {
                let q = p.source_position(b[0], b[1]);
                prop_assert!(inside(q), "border point {b:?} maps to {q:?} outside {w}x{h}");
                // Grown by one pixel on this side.
                let grown = match side {
                    0 => p.source_position(b[0] - 1.0, b[1]),
                    1 => p.source_position(b[0] + 1.0, b[1]),
                    2 => p.source_position(b[0], b[1] - 1.0),
                    _ => p.source_position(b[0], b[1] + 1.0),
                };
                let out = [-grown[0], grown[0] - fw, -grown[1], grown[1] - fh].into_iter().fold(0.0f64, f64::max);
                worst_out[side] = worst_out[side].max(out);
            }
        }
        prop_assert!(worst_out.iter().any(|&o| o > 0.0), "rectangle not tight: {worst_out:?} for {p:?}");
        prop_assert_eq!((p.fx, p.fy), (k.fx, k.fy));
    }
}

#[test]
fn keep_size_keeps_the_intrinsics() {
    let k = Intrinsics {
        fx: 300.0,
        fy: 310.0,
        cx: 110.0,
        cy: 205.0,
        distortion: Distortion {
            k1: 0.1,
            ..Distortion::NONE
        },
    };
    let p = plan(&k, 225, 400, UndistortMode::KeepSize).unwrap();
    assert_eq!(
        (p.fx, p.fy, p.cx, p.cy, p.width, p.height),
        (300.0, 310.0, 110.0, 205.0, 225, 400)
    );
    let c = plan(&k, 225, 400, UndistortMode::Crop).unwrap();
    assert!(c.width < 225 && c.height < 400, "{c:?}");
}

#[test]
fn folding_distortion_is_refused() {
    let k = Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 100.0,
        cy: 100.0,
        distortion: Distortion {
            k1: -0.9,
            ..Distortion::NONE
        },
    };
    let err = plan(&k, 200, 200, UndistortMode::Crop).unwrap_err();
    assert!(err.contains("cannot be inverted"), "{err}");
}

// ---- Straight-line check with the fox scene's stated model. ----

/// `fox/transforms.json`'s intrinsics (225×400 copy).
const FOX: (f64, f64, f64, f64, [f64; 4]) = (
    286.56666666666666,
    286.3520833333333,
    115.53291666666667,
    201.09750000000003,
    [0.0578421, -0.0805099, -0.000980296, 0.00015575],
);

fn temp_dir(tag: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("scene_distortion_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Straight lines of the pinhole image, as `(a, b, c)` with `a·u + b·v = c` (unit normal),
/// in pixels of the *original* pinhole camera (intrinsics `FOX`, before cropping).
fn lines() -> Vec<(f64, f64, f64)> {
    let diag = {
        let n = (1.0f64 / 2.0).sqrt();
        (n, -n, n * (40.0 - 60.0))
    };
    vec![
        (0.0, 1.0, 18.0),
        (0.0, 1.0, 380.0),
        (1.0, 0.0, 12.0),
        (1.0, 0.0, 212.0),
        diag,
    ]
}

/// Darkness in `[0, 1]` of a pinhole-image point: 1 on a line (1.6 px wide, soft edges).
fn ink(u: f64, v: f64) -> f64 {
    lines()
        .iter()
        .map(|&(a, b, c)| {
            let d = (a * u + b * v - c).abs();
            (1.0 - (d - 0.8).max(0.0) / 0.7).clamp(0.0, 1.0)
        })
        .fold(0.0, f64::max)
}

/// Centroids of the darkness across a line, one per row or column of `img` (values in
/// `[0, 1]`, `w × h`). The line's position in `img` is `position(t)` for coordinate `t`
/// along it; returns `(t, offset)` pairs with the measured centroid.
fn centroids(img: &[f32], w: usize, h: usize, horizontal: bool, guess: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    let (n_along, n_across) = if horizontal { (w, h) } else { (h, w) };
    let mut out = Vec::new();
    for t in 3..n_along.saturating_sub(3) {
        let g = guess(t as f64 + 0.5);
        let (lo, hi) = ((g - 4.0).floor() as i64, (g + 4.0).ceil() as i64);
        if lo < 1 || hi >= n_across as i64 - 1 {
            continue;
        }
        let (mut s, mut sw) = (0.0, 0.0);
        for a in lo..=hi {
            let idx = if horizontal {
                a as usize * w + t
            } else {
                t * w + a as usize
            };
            let dark = 1.0 - img[idx * 3] as f64;
            s += dark * (a as f64 + 0.5);
            sw += dark;
        }
        if sw > 0.5 {
            out.push((t as f64 + 0.5, s / sw));
        }
    }
    out
}

/// Least-squares straight line through `(t, y)`: returns (max |residual|, fitted line).
fn straightness(pts: &[(f64, f64)]) -> (f64, f64, f64) {
    let n = pts.len() as f64;
    let (st, sy) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
    let (mt, my) = (st / n, sy / n);
    let (sty, stt) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p.0 - mt) * (p.1 - my), b + (p.0 - mt).powi(2))
    });
    let slope = sty / stt;
    let max = pts
        .iter()
        .map(|p| (p.1 - (my + slope * (p.0 - mt))).abs())
        .fold(0.0, f64::max);
    (max, slope, my - slope * mt)
}

#[test]
fn fox_model_straight_lines_are_straight_after_loading() {
    let (fx, fy, cx, cy, [k1, k2, p1, p2]) = FOX;
    let d = Distortion {
        k1,
        k2,
        k3: 0.0,
        p1,
        p2,
    };
    let (w, h) = (225usize, 400usize);
    // Render the distorted photograph of the lines: each source pixel (4×4 supersampled) shows
    // the pinhole point obtained by undistorting its position.
    let mut photo = vec![0u8; w * h * 3];
    let mut photo_f = vec![0f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let (px, py) = (x as f64 + (sx as f64 + 0.5) / 4.0, y as f64 + (sy as f64 + 0.5) / 4.0);
                    let p = d.undistort([(px - cx) / fx, (py - cy) / fy]).unwrap();
                    acc += ink(fx * p[0] + cx, fy * p[1] + cy);
                }
            }
            let v = 1.0 - acc / 16.0;
            for c in 0..3 {
                photo[(y * w + x) * 3 + c] = (v * 255.0).round() as u8;
                photo_f[(y * w + x) * 3 + c] = v as f32;
            }
        }
    }
    let dir = temp_dir("fox_lines");
    image::save_buffer(
        dir.join("lines.png"),
        &photo,
        w as u32,
        h as u32,
        image::ColorType::Rgb8,
    )
    .unwrap();
    let json = format!(
        r#"{{"fl_x": {fx}, "fl_y": {fy}, "cx": {cx}, "cy": {cy}, "w": 225, "h": 400,
            "k1": {k1}, "k2": {k2}, "p1": {p1}, "p2": {p2},
            "frames": [{{"file_path": "lines.png",
              "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}]}}"#
    );
    std::fs::write(dir.join("transforms.json"), json).unwrap();
    let scene = load(
        &dir,
        &LoadOptions {
            test_every: 0,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(scene.format, SceneFormat::Transforms);
    let view = &scene.train[0];
    let c = view.camera;
    let (ow, oh) = (c.width as usize, c.height as usize);
    let out = view.image.get().unwrap().to_f32_rgb();
    // Shift from the original pinhole pixels to the cropped output.
    let (du, dv) = (c.cx as f64 - cx, c.cy as f64 - cy);
    println!("fox lines: undistorted image {ow}x{oh}, principal point shifted by ({du:.3}, {dv:.3})");
    for (i, &(a, b, cc)) in lines().iter().enumerate() {
        let horizontal = a.abs() < b.abs();
        // In the undistorted output the line is at a·(u − du) + b·(v − dv) = cc.
        let pos_out = |t: f64| {
            if horizontal {
                (cc - a * (t - du)) / b + dv
            } else {
                (cc - b * (t - dv)) / a + du
            }
        };
        // Coordinates along this line (output and photo) where other lines cross it.
        let crossings: Vec<(f64, f64)> = lines()
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .filter_map(|(_, &(a2, b2, c2))| {
                let det = a * b2 - b * a2;
                (det.abs() > 1e-9).then(|| ((cc * b2 - b * c2) / det, (a * c2 - cc * a2) / det))
            })
            .map(|(u, v)| {
                let q = d.distort([(u - cx) / fx, (v - cy) / fy]);
                let (pu, pv) = (fx * q[0] + cx, fy * q[1] + cy);
                if horizontal { (u + du, pu) } else { (v + dv, pv) }
            })
            .collect();
        let away = |t: f64, photo: bool| {
            crossings
                .iter()
                .all(|&(o, p)| (t - if photo { p } else { o }).abs() > 8.0)
        };
        let after: Vec<(f64, f64)> = centroids(&out, ow, oh, horizontal, pos_out)
            .into_iter()
            .filter(|p| away(p.0, false))
            .collect();
        let (bow_after, slope, icpt) = straightness(&after);
        // Offset of the fitted line from where the stated model puts it, at the middle.
        let mid = if horizontal { ow as f64 / 2.0 } else { oh as f64 / 2.0 };
        let offset = (slope * mid + icpt) - pos_out(mid);
        // Before: the same line in the distorted photograph, followed by the model's prediction.
        let pos_in = |t: f64| {
            // Walk along the pinhole line and distort it: find the photo position for coordinate t.
            let mut best = (f64::MAX, 0.0);
            for k in 0..4000 {
                let s = -200.0 + k as f64 * 0.2;
                let (u, v) = if horizontal {
                    (s, (cc - a * s) / b)
                } else {
                    ((cc - b * s) / a, s)
                };
                let q = d.distort([(u - cx) / fx, (v - cy) / fy]);
                let (px, py) = (fx * q[0] + cx, fy * q[1] + cy);
                let (along, across) = if horizontal { (px, py) } else { (py, px) };
                if (along - t).abs() < best.0 {
                    best = ((along - t).abs(), across);
                }
            }
            best.1
        };
        let before: Vec<(f64, f64)> = centroids(&photo_f, w, h, horizontal, pos_in)
            .into_iter()
            .filter(|p| away(p.0, true))
            .collect();
        let (bow_before, _, _) = straightness(&before);
        let before_text = if i < 4 {
            format!("{bow_before:.3} px")
        } else {
            "(not measured)".to_string()
        };
        println!(
            "fox lines: line {i}: max deviation from a straight line {before_text} in the distorted photo, \
             {bow_after:.3} px after loading ({} samples); offset from the predicted position {offset:.3} px",
            after.len()
        );
        assert!(after.len() > 100);
        assert!(bow_after < 0.1, "line {i} still bent by {bow_after} px");
        assert!(offset.abs() < 0.1, "line {i} moved by {offset} px");
        if i < 4 {
            assert!(
                bow_before > 3.0 * bow_after,
                "line {i}: the test image shows no distortion"
            );
        }
    }
}
