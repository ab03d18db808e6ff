//! The raw billboard model: the reference's initial alpha texture, and initialisation from points.

use bbsplat::model::{RawBillboards, initial_alpha};
use bbsplat::stages::sh::rgb_to_sh;
use glam::Vec3;

#[test]
fn initial_alpha_matches_the_reference() {
    let a = initial_alpha(16);
    assert_eq!(a.iter().filter(|&&x| x == 0.0).count(), 15);
    let peak = a.iter().cloned().fold(0.0, f32::max);
    assert!((peak - 0.5 * 251.0 / 255.0).abs() < 1e-6);
    let mean = a.iter().sum::<f32>() / 256.0;
    assert!((mean - 0.0875).abs() < 1e-3, "{mean}");
    // Resampled sizes keep the corners at zero and the peak near the centre.
    let a8 = initial_alpha(8);
    assert_eq!(a8[0], 0.0);
    assert!(a8[3 * 8 + 3] > 0.3);
}

#[test]
fn masked_texels_stay_zero_and_scales_follow_neighbours() {
    let pts = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::splat(5.0)];
    let m = RawBillboards::from_points(&pts, &[[0.5; 3]; 5], 16, 0);
    let b = m.activate();
    assert_eq!(b.textures[0][3], 0.0);
    assert!((b.textures[7][1] - 0.1).abs() < 1e-6);
    // Point 0 has three neighbours at distance 1: log-scale ln(1) = 0.
    assert!(m.log_scales[0].x.abs() < 1e-6);
    // SH DC reproduces the point colour minus 0.1 in SH units.
    assert!((m.sh[0] - (rgb_to_sh(0.5) - 0.1)).abs() < 1e-6);
}
