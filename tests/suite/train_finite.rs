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

/// The gradient check with the regularisers' row gradients added as the texture step will add
/// them (`non_finite_gradient_with`) gives the answer of adding them in place and checking: for
/// finite gradients, a NaN or an infinity in a colour or the alpha lane, and finite gradients
/// that only the addition makes infinite (`f32::MAX` plus a positive regulariser gradient, in
/// either lane), which a check of the gradients alone would miss.
#[test]
fn the_check_with_regulariser_rows_sees_what_the_texture_step_will_read() {
    use bbsplat::raster::RenderGradients;
    use bbsplat::train::finite::{non_finite_gradient, non_finite_gradient_with};
    use bbsplat::train::regularise::{RowGradient, TextureTerm, regularise, regulariser_rows};
    let (rows, ts) = (6usize, 4usize);
    let texels = ts * ts;
    let activated: Vec<[f32; 4]> = (0..rows * texels)
        .map(|i| [0.3, 0.6, 0.2, 0.1 + 0.8 * ((i % 5) as f32 / 5.0)])
        .collect();
    let alpha0 = vec![0.2f32; texels];
    let impact = vec![10.0f32; rows];
    let term = TextureTerm {
        alpha0: &alpha0,
        impact: &impact,
        threshold: 500.0,
        // Weights large enough that the regulariser gradients (about 1e35) move `f32::MAX`
        // by more than half its ulp (2¹⁰³).
        weight: 1e37,
    };
    let mut added: Vec<RowGradient> = Vec::new();
    regulariser_rows(
        &activated,
        texels,
        Some(term),
        Some(1e37),
        &mut added,
        bbsplat::cpu::Simd::detect(),
    );
    let (gc, ga) = added[3].texture.expect("the term weighs row 3");
    assert!(
        gc > 1e32 && ga > 1e32 && added[3].opacity.is_some_and(|g| g > 1e32),
        "{gc:e} {ga:e}"
    );
    let cases: [(usize, usize, f32); 7] = [
        (0, 0, 0.5),
        (3, 1, f32::NAN),
        (3, 3, f32::INFINITY),
        (3, 0, f32::MAX),
        (3, 3, f32::MAX),
        (5, 2, -f32::MAX),
        (2, 3, f32::MIN_POSITIVE),
    ];
    let mut overflows = 0;
    for (row, channel, value) in cases {
        let mut g = RenderGradients::zeros(rows, ts);
        g.textures[row * texels + 5][channel] = value;
        let mut in_place = g.clone();
        regularise(
            &activated,
            texels,
            Some(term),
            Some(1e37),
            &mut in_place.textures,
            bbsplat::cpu::Simd::detect(),
        );
        let want = non_finite_gradient(&in_place);
        assert_eq!(
            non_finite_gradient_with(&g, Some(&added)),
            want,
            "row {row} lane {channel} {value:e}"
        );
        if value.is_finite() && want.is_some() {
            overflows += 1;
            assert_eq!(non_finite_gradient(&g), None, "only the addition overflows");
        }
    }
    assert_eq!(
        overflows, 2,
        "f32::MAX in a colour and in the alpha lane overflow once added"
    );
}
