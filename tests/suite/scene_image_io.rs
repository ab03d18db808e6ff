//! Image resizing on load: the area resize and the target sizes.

use bbsplat::testing_internals::scene::{resize_area, target_size};

#[test]
fn area_resize_averages_blocks() {
    // 4×2 → 2×1: each output pixel is the mean of a 2×2 block.
    let src: Vec<f32> = (0..8).flat_map(|i| [i as f32, 0.0, 1.0]).collect();
    let out = resize_area(&src, 4, 2, 2, 1);
    assert_eq!(out.len(), 6);
    assert!((out[0] - (0.0 + 1.0 + 4.0 + 5.0) / 4.0).abs() < 1e-6);
    assert!((out[3] - (2.0 + 3.0 + 6.0 + 7.0) / 4.0).abs() < 1e-6);
    assert!((out[2] - 1.0).abs() < 1e-6);
}

#[test]
fn area_resize_preserves_constant_for_odd_ratios() {
    let src = vec![0.25f32; 7 * 5 * 3];
    let out = resize_area(&src, 7, 5, 3, 2);
    assert!(out.iter().all(|v| (v - 0.25).abs() < 1e-6));
}

#[test]
fn target_sizes() {
    assert_eq!(target_size(225, 400, 2, None), (113, 200));
    assert_eq!(target_size(400, 400, 4, None), (100, 100));
    assert_eq!(target_size(1600, 1200, 1, Some(800)), (800, 600));
    assert_eq!(target_size(3, 3, 8, None), (1, 1));
}
