//! Non-finite detection: every bad value found at any position, gradient and parameter groups named.

use bbsplat::model::RawBillboards;
use bbsplat::raster::RenderGradients;
use bbsplat::testing_internals::train::FINITE_SCAN_CHUNK as CHUNK;
use bbsplat::train::ParamGroup;
use bbsplat::train::finite::{all_finite, non_finite_gradient, non_finite_parameter};
use glam::Vec3;

#[test]
fn every_non_finite_value_is_found_at_any_position() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
        for len in [1, 7, CHUNK - 1, CHUNK + 5, 3 * CHUNK] {
            for at in [0, len / 2, len - 1] {
                let mut xs = vec![1.5f32; len];
                xs[at] = bad;
                assert!(!all_finite(&xs), "{bad} at {at} of {len}");
            }
        }
    }
    let extremes = [f32::MAX, f32::MIN, f32::MIN_POSITIVE, 1e-45, -0.0, 0.0];
    assert!(all_finite(&extremes));
    assert!(all_finite(&[]));
}

#[test]
fn gradient_groups_are_named() {
    let mut g = RenderGradients::zeros(3, 2);
    assert_eq!(non_finite_gradient(&g), None);
    g.textures[5][1] = f32::NAN;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::ColourTextures));
    g.textures[7][3] = f32::INFINITY;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::AlphaTextures));
    g.sh[100] = f32::NAN;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::Sh));
    g.log_scales[2].y = f32::NAN;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::LogScales));
    g.quaternions[1][0] = f32::NEG_INFINITY;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::Quaternions));
    g.positions[0].z = f32::NAN;
    assert_eq!(non_finite_gradient(&g), Some(ParamGroup::Positions));
}

#[test]
fn parameter_groups_are_named() {
    let points = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let mut m = RawBillboards::from_points(&points, &[[0.5; 3]; 3], 4, 0);
    let mut o = vec![0.0; 3];
    assert_eq!(non_finite_parameter(&m, &o), None);
    o[2] = f32::NAN;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::Opacity));
    m.colour_logits[9] = f32::INFINITY;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::ColourTextures));
    m.alpha_logits[3] = f32::NAN;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::AlphaTextures));
    m.sh[50] = f32::NAN;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::Sh));
    m.log_scales[1].x = f32::NAN;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::LogScales));
    m.quaternions[2][3] = f32::NAN;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::Quaternions));
    m.positions[1].x = f32::INFINITY;
    assert_eq!(non_finite_parameter(&m, &o), Some(ParamGroup::Positions));
}
