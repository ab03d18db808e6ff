//! Fuzzing entry points: run a parser on arbitrary bytes and check its invariants.
//!
//! Each function must never panic on any input except to report a broken invariant (a bug).
//! They are called by the cargo-fuzz targets in `fuzz/` and by the mutation property test
//! `tests/suite/scene_fuzz.rs`. Invariants checked on inputs that parse:
//! - COLMAP binary: writing the parsed records reproduces the input bytes exactly (the layout
//!   has no slack, so parse is injective);
//! - COLMAP text: write-then-parse gives the same records (compared through `Debug`, so that
//!   NaN keypoints compare equal);
//! - transforms JSON: intrinsics resolve without panicking for a few image sizes;
//! - PLY: positions are finite and colours lie in `[0, 1]`.
//! - `.npy` (LLFF `poses_bounds.npy`): the values fill the shape; an f8 array written back
//!   parses to the same bits; rows of a pose file have `0 < near < far`.
//! - `.npz` (NeuS `cameras_sphere.npz`): every member parses or fails without a panic; every
//!   camera that decomposes has a rotation with orthonormal rows and `det = +1` and intrinsics
//!   with a positive diagonal.
//!
//! ```
//! bbsplat::scene::fuzz::colmap_binary(&[0, 1, 0, 0, 0, 0, 0, 0, 0]);
//! bbsplat::scene::fuzz::colmap_text(b"\x01# comment\n1 2 3");
//! bbsplat::scene::fuzz::transforms(b"{\"frames\": []}");
//! bbsplat::scene::fuzz::npy(b"\x93NUMPY\x01\x00");
//! bbsplat::scene::fuzz::npz(b"PK\x05\x06");
//! ```

use super::{colmap_binary as bin, colmap_text as txt, llff, nerf_json, neus, npy as np, ply, projection};
use std::path::Path;

/// `data[0] % 3` selects `cameras.bin`, `images.bin` or `points3D.bin`; the rest is the file.
pub fn colmap_binary(data: &[u8]) {
    let Some((&which, bytes)) = data.split_first() else {
        return;
    };
    let f = Path::new("fuzz.bin");
    let rewritten = match which % 3 {
        0 => bin::parse_cameras(bytes, f).ok().map(|c| bin::write_cameras(&c)),
        1 => bin::parse_images(bytes, f).ok().map(|i| bin::write_images(&i)),
        _ => bin::parse_points(bytes, f).ok().map(|p| bin::write_points(&p)),
    };
    if let Some(out) = rewritten {
        assert_eq!(out, bytes, "binary write(parse(x)) != x");
    }
}

/// `data[0] % 3` selects `cameras.txt`, `images.txt` or `points3D.txt`; the rest is the file
/// (decoded as UTF-8 first, as the loader does).
pub fn colmap_text(data: &[u8]) {
    let Some((&which, bytes)) = data.split_first() else {
        return;
    };
    let f = Path::new("fuzz.txt");
    let Ok(text) = txt::decode_utf8(bytes, f) else {
        return;
    };
    match which % 3 {
        0 => {
            if let Ok(c) = txt::parse_cameras(text, f) {
                let back = txt::parse_cameras(&txt::write_cameras(&c), f).expect("re-parse of written cameras");
                assert_eq!(format!("{back:?}"), format!("{c:?}"));
            }
        }
        1 => {
            if let Ok(i) = txt::parse_images(text, f) {
                let written = txt::write_images(&i).expect("parsed names are writable");
                let back = txt::parse_images(&written, f).expect("re-parse of written images");
                assert_eq!(format!("{back:?}"), format!("{i:?}"));
            }
        }
        _ => {
            if let Ok(p) = txt::parse_points(text, f) {
                let back = txt::parse_points(&txt::write_points(&p), f).expect("re-parse of written points");
                assert_eq!(format!("{back:?}"), format!("{p:?}"));
            }
        }
    }
}

/// A transforms JSON file (NeRF-synthetic or instant-ngp/nerfstudio).
pub fn transforms(data: &[u8]) {
    let f = Path::new("transforms.json");
    let Ok(text) = txt::decode_utf8(data, f) else {
        return;
    };
    if let Ok(t) = nerf_json::parse_transforms(text, f) {
        for frame in &t.frames {
            for (w, h) in [(1, 1), (800, 600)] {
                if let Ok((k, _, _)) = frame.intrinsics.resolve(&t.intrinsics, w, h) {
                    assert!(k.fx > 0.0 && k.fy > 0.0);
                }
            }
        }
    }
}

/// A PLY point cloud.
pub fn ply(data: &[u8]) {
    if let Ok(cloud) = ply::parse_point_cloud(data, Path::new("fuzz.ply")) {
        assert_eq!(cloud.positions.len(), cloud.colours.len());
        assert!(cloud.positions.iter().all(|p| p.is_finite()));
        assert!(cloud.colours.iter().flatten().all(|c| (0.0..=1.0).contains(c)));
    }
}

/// An `.npy` array, then the same bytes as an LLFF `poses_bounds.npy`.
pub fn npy(data: &[u8]) {
    let f = Path::new("poses_bounds.npy");
    if let Ok(array) = np::parse_npy(data) {
        assert_eq!(array.data.len(), array.shape.iter().product::<usize>());
        let header = np::parse_header(data).expect("a parsed array has a header");
        if header.dtype == np::Dtype::F64 {
            let back =
                np::parse_npy(&np::write_npy_f64(&array.shape, &array.data)).expect("re-parse of a written array");
            let bits = |a: &np::NpyArray| a.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!((back.shape.clone(), bits(&back)), (array.shape.clone(), bits(&array)));
        }
    }
    if let Ok(poses) = llff::parse_poses(data, f) {
        for p in &poses {
            assert!(p.bounds[0] > 0.0 && p.bounds[1] > p.bounds[0]);
            assert!(p.hwf.iter().all(|v| *v > 0.0));
        }
    }
}

/// An `.npz` archive, read as NeuS/IDR cameras (`world_mat_i` · `scale_mat_i`, or `world_mat_i`
/// alone when the scale is missing).
pub fn npz(data: &[u8]) {
    let f = Path::new("cameras_sphere.npz");
    let Ok(archive) = np::Npz::parse(data) else {
        return;
    };
    let names: Vec<String> = archive.names().map(str::to_string).collect();
    for name in &names {
        let _ = archive.array(name).expect("a listed member exists");
    }
    for i in 0..names.len() {
        let Ok(world) = neus::matrix(&archive, f, &format!("world_mat_{i}")) else {
            continue;
        };
        let scale = neus::matrix(&archive, f, &format!("scale_mat_{i}")).unwrap_or(glam::DMat4::IDENTITY);
        let p = (world * scale).transpose().to_cols_array_2d();
        if let Ok(d) = projection::decompose_projection(&[p[0], p[1], p[2]]) {
            let r = glam::DMat3::from_cols_array_2d(&d.rotation);
            assert!(
                (r * r.transpose() - glam::DMat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .all(|v| v.abs() < 1e-6)
            );
            assert!((r.determinant() - 1.0).abs() < 1e-6);
            assert!(d.k[0][0] > 0.0 && d.k[1][1] > 0.0 && d.k[2][2] == 1.0);
        }
    }
}
