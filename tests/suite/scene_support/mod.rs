//! Helpers shared by the scene tests: temporary folders and small synthetic datasets.

use bbsplat::scene::colmap::{
    CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint3D, Point2D, TrackElement,
};
use bbsplat::scene::{colmap_binary, colmap_text};
use std::path::{Path, PathBuf};

/// A fresh, empty folder under the cargo target's temporary directory.
pub fn temp_dir(tag: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("scene_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Two bytes that tell the images of a dataset apart (FNV-1a of the file name and its folder's
/// name, so that two datasets written alike have the same images): the loader leaves out
/// frames that are copies of each other ([`bbsplat::scene::duplicates`]).
fn mark(path: &Path) -> [u8; 2] {
    let tail: PathBuf = path
        .iter()
        .rev()
        .take(2)
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let h = tail.to_string_lossy().bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    });
    [(h >> 8) as u8, (h >> 16) as u8]
}

/// Writes an RGB PNG whose pixel (x, y) is `(8x, 8y, 100)` (mod 256), but for the bottom-right
/// pixel, which holds a mark of the path (so that no two files are the same image).
pub fn write_png(path: &Path, w: u32, h: u32) {
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            data.extend([(8 * x % 256) as u8, (8 * y % 256) as u8, 100]);
        }
    }
    let [a, b] = mark(path);
    let last = data.len() - 3;
    data[last + 1] = a;
    data[last + 2] = b;
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::save_buffer(path, &data, w, h, image::ColorType::Rgb8).unwrap();
}

/// Writes an RGBA PNG: opaque red left half, fully transparent right half, half-transparent
/// green bottom row; the last opaque pixel of the row above it holds a mark of the path (so that
/// no two files are the same image).
pub fn write_rgba_png(path: &Path, w: u32, h: u32) {
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            if y == h - 1 {
                data.extend([0, 255, 0, 128]);
            } else if x < w / 2 {
                data.extend([255, 0, 0, 255]);
            } else {
                data.extend([10, 20, 30, 0]);
            }
        }
    }
    if h >= 2 && w >= 2 {
        let [a, b] = mark(path);
        let i = (((h - 2) * w + w / 2 - 1) * 4) as usize;
        data[i + 1] = a;
        data[i + 2] = b;
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::save_buffer(path, &data, w, h, image::ColorType::Rgba8).unwrap();
}

/// A small valid model: cameras 7 (PINHOLE 32×24) and 9 (SIMPLE_RADIAL 32×24), images named
/// `img_0.png` .. `img_{n-1}.png` on a circle of radius 3 looking at the origin, 3 points.
pub fn model(n: usize) -> ColmapModel {
    let cameras = vec![
        ColmapCamera {
            id: 7,
            model: CameraModel::Pinhole,
            width: 32,
            height: 24,
            params: vec![30.0, 31.0, 16.0, 12.0],
        },
        ColmapCamera {
            id: 9,
            model: CameraModel::SimpleRadial,
            width: 32,
            height: 24,
            params: vec![30.0, 16.5, 11.5, 0.02],
        },
    ];
    let images = (0..n)
        .map(|i| {
            // Rotation about the world y axis by angle a; camera centre at -Rᵀt = 3·(sin a, 0, -cos a)... kept simple:
            let a = i as f64 * 0.3;
            let (s, c) = ((a / 2.0).sin(), (a / 2.0).cos());
            ColmapImage {
                id: 100 + i as u32,
                qvec: [c, 0.0, s, 0.0],
                tvec: [0.0, 0.0, 3.0],
                camera_id: if i % 2 == 0 { 7 } else { 9 },
                name: format!("img_{i}.png"),
                points2d: vec![Point2D {
                    xy: [16.0, 12.0],
                    point3d_id: 1,
                }],
            }
        })
        .collect();
    let points = vec![
        ColmapPoint3D {
            id: 1,
            xyz: [0.0, 0.0, 0.0],
            rgb: [255, 0, 0],
            error: 0.1,
            track: vec![TrackElement {
                image_id: 100,
                point2d_idx: 0,
            }],
        },
        ColmapPoint3D {
            id: 2,
            xyz: [0.5, 0.2, -0.1],
            rgb: [0, 255, 0],
            error: 0.2,
            track: vec![],
        },
        ColmapPoint3D {
            id: 3,
            xyz: [1000.0, 0.0, 0.0],
            rgb: [0, 0, 255],
            error: 0.3,
            track: vec![],
        },
    ];
    ColmapModel {
        cameras,
        images,
        points,
    }
}

/// Writes `model(n)` as `dir/sparse/0` (binary or text) with its images in `dir/images`.
pub fn colmap_dataset(dir: &Path, n: usize, binary: bool) -> ColmapModel {
    let m = model(n);
    let sparse = dir.join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    if binary {
        colmap_binary::write_model(&m, &sparse).unwrap();
    } else {
        colmap_text::write_model(&m, &sparse).unwrap();
    }
    for im in &m.images {
        write_png(&dir.join("images").join(&im.name), 32, 24);
    }
    m
}

/// A transforms.json frame (OpenGL camera-to-world, camera at `(0, 0, z)` looking at -z).
pub fn frame(path: &str, z: f64) -> String {
    format!(r#"{{"file_path": "{path}", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,{z}],[0,0,0,1]]}}"#)
}
