//! The lane-wise forms of the ray-plane and bilinear stages (`intersect_lanes`, `taps_row`) and of
//! the support quad's row spans (`SupportQuad::row_spans`), which
//! the rasterizer's tile loops run, against the scalar forms that carry the gradient proofs:
//! equal bit for bit, lane by lane, on random visible billboards, on pixels far outside them,
//! on degenerate transforms (edge-on, zero, NaN, infinite), at texel borders and outside the
//! texture. Each test runs under both instruction-set builds of this process's code paths where
//! that matters (the rasterizer's, in `raster_lanes.rs`); here the functions are called directly.

use bbsplat::camera::Camera;
use bbsplat::stages::bilinear::{BilinearTaps, taps, taps_row};
use bbsplat::stages::ray_plane::{
    LANES, ViewPlane, intersect_lanes, intersect_vjp_lanes, intersect_vjp_with, intersect_with, pixel_ray, row_centres,
};
use bbsplat::stages::splat_transform::{ROW_LANES, SplatTransform, SupportQuad, splat_frame, view_plane};
use bbsplat::strategies::{billboard_in_front, camera, seeded_config};
use bbsplat::testing_internals::bilinear::{refilled_taps_row, sampling_taps_row, vjp_rgba_lanes};
use glam::{Vec2, Vec3};
use proptest::prelude::*;

/// Compares every lane of `intersect_lanes` and `intersect_vjp_lanes` with the scalar
/// intersection and its backward, bit for bit.
fn check_row(
    t: &SplatTransform,
    plane: &ViewPlane,
    cam: &Camera,
    px: &[f32; LANES],
    py: &[f32; LANES],
) -> Result<(), String> {
    let row = intersect_lanes(t, plane, cam, px, py);
    for lane in 0..LANES {
        let (x, y) = (px[lane], py[lane]);
        let scalar = intersect_with(t, x, y, |_, _| plane.depth(pixel_ray(cam, x, y)));
        match scalar {
            None if row.valid[lane] => return Err(format!("lane {lane} ({x}, {y}): valid, scalar None")),
            None => {}
            Some(h) => {
                let lane_hit = [row.u[lane], row.v[lane], row.depth[lane]].map(f32::to_bits);
                if !row.valid[lane] || lane_hit != [h.u, h.v, h.depth].map(f32::to_bits) {
                    return Err(format!(
                        "lane {lane} ({x}, {y}): lanes ({}, {}, {}, valid {}), scalar {h:?}",
                        row.u[lane], row.v[lane], row.depth[lane], row.valid[lane]
                    ));
                }
            }
        }
    }
    // The backward, lane-wise, against the scalar backward (zero where the scalar misses).
    let d_u: [f32; LANES] = std::array::from_fn(|l| 0.7 - 0.3 * l as f32);
    let d_v: [f32; LANES] = std::array::from_fn(|l| -1.1 + 0.2 * l as f32);
    let d_depth: [f32; LANES] = std::array::from_fn(|l| 0.05 * l as f32 - 0.2);
    let lanes = intersect_vjp_lanes(t, &row, (px, py), (&d_u, &d_v, &d_depth));
    for lane in 0..LANES {
        let (x, y) = (px[lane], py[lane]);
        let ray = pixel_ray(cam, x, y);
        let scalar = intersect_vjp_with(t, x, y, |_, _| plane.depth(ray), d_u[lane], d_v[lane], d_depth[lane]);
        if lanes.lane(lane).to_array().map(f32::to_bits) != scalar.to_array().map(f32::to_bits) {
            return Err(format!(
                "lane {lane} ({x}, {y}): backward {:?} against {scalar:?}",
                lanes.lane(lane)
            ));
        }
    }
    Ok(())
}

/// The bits of every field of a tap set (indices, weights, both weight derivatives).
fn tap_bits(t: &BilinearTaps) -> Vec<u32> {
    let mut bits = t.indices().to_vec();
    for part in [t.weights(), t.weight_derivatives_u(), t.weight_derivatives_v()] {
        bits.extend(part.iter().map(|w| w.to_bits()));
    }
    bits
}

/// A `ts × ts` RGBA texture of values in [0, 1) (fixed by `seed`).
fn texture(ts: usize, seed: u64) -> Vec<[f32; 4]> {
    let mut rng = bbsplat::rng::Rng::new(seed);
    (0..ts * ts).map(|_| [(); 4].map(|_| rng.uniform())).collect()
}

/// Compares every lane of `taps_row` (its taps and its sampling taps) with the scalar `taps`,
/// bit for bit.
fn check_taps(u: &[f32; LANES], v: &[f32; LANES], ts: usize) -> Result<(), String> {
    let row = taps_row(u, v, ts);
    // Refilled in place over the taps of other coordinates, as the tile loops make them: the
    // same values in every field.
    let refilled = refilled_taps_row(taps_row(v, u, ts), true, u, v, ts);
    if format!("{refilled:?}") != format!("{row:?}") {
        return Err(format!("refilled taps differ: {refilled:?} against {row:?}"));
    }
    for lane in 0..LANES {
        let scalar = taps(u[lane], v[lane], ts);
        let lane_taps = row.lane(lane);
        if scalar.as_ref().map(tap_bits) != lane_taps.as_ref().map(tap_bits) {
            return Err(format!(
                "lane {lane} ({}, {}): {lane_taps:?} against {scalar:?}",
                u[lane], v[lane]
            ));
        }
        let sampling = row.lane_for_sampling(lane);
        if sampling != scalar.map(|t| t.for_sampling()) {
            return Err(format!("lane {lane} ({}, {}): sampling taps differ", u[lane], v[lane]));
        }
    }
    Ok(())
}

/// Compares every lane's sample and sample backward read straight from the lanes
/// (`RowTaps::sample_rgba`, `RowTaps::vjp_rgba`) with the scalar ones, bit for bit.
fn check_samples(u: &[f32; LANES], v: &[f32; LANES], ts: usize) -> Result<(), String> {
    check_samples_of(u, v, ts, |lane| texture(ts, lane as u64))
}

/// [`check_samples`] on the textures `texture_of(lane)`.
fn check_samples_of(
    u: &[f32; LANES],
    v: &[f32; LANES],
    ts: usize,
    texture_of: impl Fn(usize) -> Vec<[f32; 4]>,
) -> Result<(), String> {
    let row = taps_row(u, v, ts);
    // The forward pass's taps, made without the weights' derivatives, sample the same bits.
    let sampling_row = sampling_taps_row(u, v, ts);
    // And so do the sampling taps refilled in place over others (whose stale derivatives stay).
    let refilled_row = refilled_taps_row(taps_row(v, u, ts), false, u, v, ts);
    // Every NaN counts as one value: Rust does not specify NaN payloads and signs.
    let value_bits = |c: f32| if c.is_nan() { f32::NAN.to_bits() } else { c.to_bits() };
    let bits = |x: [f32; 4]| x.map(value_bits);
    for lane in 0..LANES {
        let scalar = taps(u[lane], v[lane], ts);
        let texels = texture_of(lane);
        let sampled = row.sample_rgba(lane, &texels).map(bits);
        if sampling_row.sample_rgba(lane, &texels).map(bits) != sampled
            || refilled_row.sample_rgba(lane, &texels).map(bits) != sampled
        {
            return Err(format!(
                "lane {lane} ({}, {}): sampling-only taps sample differently",
                u[lane], v[lane]
            ));
        }
        if sampled != scalar.map(|t| bits(t.sample_rgba(&texels))) {
            return Err(format!(
                "lane {lane} ({}, {}): samples differ: {:?} against {:?}",
                u[lane],
                v[lane],
                row.sample_rgba(lane, &texels),
                scalar.map(|t| t.sample_rgba(&texels))
            ));
        }
        let d_rgba = [0.3, -1.7, 0.05, 2.5];
        let mut lane_emitted = Vec::new();
        let lane_vjp = row.vjp_rgba(lane, &texels, d_rgba, |i, g| lane_emitted.push((i, bits(g))));
        let mut emitted = Vec::new();
        let vjp = scalar.map(|t| t.vjp_rgba(&texels, d_rgba, |i, g| emitted.push((i, bits(g)))));
        let pair_bits = |p: Option<(f32, f32)>| p.map(|(a, b)| bits([a, b, 0.0, 0.0]));
        if pair_bits(lane_vjp) != pair_bits(vjp) || lane_emitted != emitted {
            return Err(format!("lane {lane} ({}, {}): backward differs", u[lane], v[lane]));
        }
    }
    // The chunk form on one texture (lane 0's), with a gradient per lane and some lanes off:
    // lane by lane the per-lane backward, its emits in lane order, and (0, 0) where it gives
    // `None` or the lane is off.
    let texels = texture_of(0);
    for off in [usize::MAX, 1, 2] {
        let active: [bool; LANES] = std::array::from_fn(|l| l % 3 != off);
        let d_rgba: [[f32; 4]; LANES] =
            std::array::from_fn(|l| [0.3 + l as f32, -1.7, 0.05 * l as f32, 2.5 - l as f32]);
        let mut chunk_emitted = Vec::new();
        let (du, dv) = vjp_rgba_lanes(&row, &texels, &d_rgba, &active, |i, g| chunk_emitted.push((i, bits(g))));
        let mut emitted = Vec::new();
        for lane in 0..LANES {
            let expected = if active[lane] {
                row.vjp_rgba(lane, &texels, d_rgba[lane], |i, g| emitted.push((i, bits(g))))
            } else {
                None
            };
            let (eu, ev) = expected.unwrap_or_default();
            if bits([du[lane], dv[lane], 0.0, 0.0]) != bits([eu, ev, 0.0, 0.0]) {
                return Err(format!(
                    "lane {lane} ({}, {}), lanes off {off}: chunk backward ({}, {}) against ({eu}, {ev})",
                    u[lane], v[lane], du[lane], dv[lane]
                ));
            }
        }
        if chunk_emitted != emitted {
            return Err(format!("lanes off {off}: the chunk backward emits differently"));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(seeded_config(256))]

    /// Visible billboards, pixels through them and beyond (misses included), on one row or on
    /// three.
    #[test]
    fn intersect_lanes_equals_the_scalar_intersection(
        (cam, pose) in camera().prop_flat_map(|c| (Just(c), billboard_in_front(c))),
        fy in 0.0f32..1.0,
        fx in 0.0f32..1.0,
        spacing in prop_oneof![Just(1.0f32), 0.1f32..40.0],
        rows in prop_oneof![Just(0.0f32), 1.0f32..20.0],
    ) {
        let frame = splat_frame(pose.position, pose.log_scales, pose.quaternion, &cam).unwrap();
        let (normal, offset) = view_plane(pose.position, pose.quaternion, &cam, frame.normal_sign);
        let plane = ViewPlane { normal, offset };
        let py = (fy * cam.height as f32).floor() + 0.5;
        let x0 = (fx * cam.width as f32).floor() + 0.5;
        let px: [f32; LANES] = std::array::from_fn(|l| x0 + l as f32 * spacing);
        let py: [f32; LANES] = std::array::from_fn(|l| py + (l % 3) as f32 * rows);
        check_row(&frame.transform, &plane, &cam, &px, &py).map_err(TestCaseError::fail)?;
    }

    /// Coordinates around and beyond the texture, with exact texel borders mixed in.
    #[test]
    fn taps_row_equals_the_scalar_taps(
        u in prop::array::uniform8(prop_oneof![-1.3f32..1.3, (0u32..16).prop_map(|k| -1.0 + 2.0 * k as f32 / 15.0)]),
        v in prop::array::uniform8(prop_oneof![-1.3f32..1.3, (0u32..16).prop_map(|k| -1.0 + 2.0 * k as f32 / 15.0)]),
        ts in prop_oneof![Just(16usize), 2usize..40],
    ) {
        check_taps(&u, &v, ts).map_err(TestCaseError::fail)?;
        check_samples(&u, &v, ts).map_err(TestCaseError::fail)?;
    }
}

/// Degenerate transforms: edge-on (p.z = 0 everywhere), all zero, NaN and infinite entries, a
/// plane behind the camera, and a plane whose hits cross the near plane along the row.
#[test]
fn intersect_lanes_rejects_exactly_what_the_scalar_form_rejects() {
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 60.0, 60.0, 64, 48);
    let face_on = SplatTransform {
        tu: Vec3::new(30.0, 0.0, 32.0),
        tv: Vec3::new(0.0, 30.0, 24.0),
        tw: Vec3::new(0.0, 0.0, 4.0),
    };
    let edge_on = SplatTransform {
        tu: Vec3::new(30.0, 0.0, 32.0),
        tv: Vec3::new(60.0, 0.0, 64.0),
        tw: Vec3::new(0.0, 0.0, 4.0),
    };
    let mut nan = face_on;
    nan.tw.x = f32::NAN;
    let mut inf = face_on;
    inf.tu.y = f32::INFINITY;
    let plane = ViewPlane {
        normal: Vec3::new(0.0, 0.0, -1.0),
        offset: -4.0,
    };
    let behind = ViewPlane {
        normal: Vec3::new(0.0, 0.0, -1.0),
        offset: 4.0,
    };
    // A plane seen very obliquely: hit depths run from far to below the near plane along x.
    let oblique = ViewPlane {
        normal: Vec3::new(0.999, 0.0, -0.0447).normalize(),
        offset: -0.1,
    };
    let nan_plane = ViewPlane {
        normal: Vec3::new(f32::NAN, 0.0, -1.0),
        offset: -4.0,
    };
    let mut checked = 0;
    for t in [face_on, edge_on, SplatTransform::default(), nan, inf] {
        for p in [plane, behind, oblique, nan_plane] {
            for x0 in [0.5f32, 28.5, 60.5, -100.5, 1e30] {
                for py in [0.5f32, 23.5, 47.5, f32::NAN] {
                    let px: [f32; LANES] = std::array::from_fn(|l| x0 + l as f32);
                    check_row(&t, &p, &cam, &px, &[py; LANES]).unwrap();
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 400);
}

/// Non-finite, huge and boundary coordinates, and the smallest and a large texture size.
#[test]
fn taps_row_handles_non_finite_and_boundary_coordinates() {
    let specials = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        -1.0,
        1.0,
        1.0 + 2.0 / 15.0,
        -1.0 - 2.0 / 15.0,
        0.0,
        -0.0,
        f32::MIN_POSITIVE,
    ];
    for ts in [2usize, 16, 65536] {
        for &a in &specials {
            let u: [f32; LANES] = std::array::from_fn(|l| if l % 2 == 0 { a } else { specials[l] });
            let v: [f32; LANES] = std::array::from_fn(|l| specials[(l + 3) % specials.len()]);
            check_taps(&u, &v, ts).unwrap();
            check_taps(&v, &u, ts).unwrap();
            // Sampling needs the texture (a 65536² one would be 64 GiB).
            if ts <= 16 {
                check_samples(&u, &v, ts).unwrap();
                check_samples(&v, &u, ts).unwrap();
            }
        }
    }
}

/// On the border ring (`X` or `Y` in `[−1, 0)` or `[ts − 1, ts)`) the lanes keep all four taps
/// and replace the outside taps' products by zero: with infinite and NaN texels next to the
/// border (where `0 · ∞` would be NaN) the samples and backward are still the scalar ones, bit
/// for bit.
#[test]
fn border_lanes_with_non_finite_texels_equal_the_scalar_taps() {
    let specials = [f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 3.0e38, -0.0, 0.5];
    let ts = 16;
    // Coordinates on the ring and just inside it, on every side.
    let edge = 2.0 / (ts - 1) as f32;
    let ring = [
        -1.0 - 0.5 * edge,
        -1.0 - 0.99 * edge,
        -1.0,
        1.0,
        1.0 + 0.5 * edge,
        1.0 + 0.99 * edge,
        0.0,
        -0.999,
    ];
    let mut checked = 0;
    for (i, &a) in ring.iter().enumerate() {
        let u: [f32; LANES] = std::array::from_fn(|l| ring[(l + i) % ring.len()]);
        let v: [f32; LANES] = std::array::from_fn(|l| if l % 2 == 0 { a } else { ring[(l * 3 + i) % ring.len()] });
        for (s, _) in specials.iter().enumerate() {
            let texels = |lane: usize| -> Vec<[f32; 4]> {
                (0..ts * ts)
                    .map(|t| [0, 1, 2, 3].map(|c| specials[(t * 7 + c + lane + s) % specials.len()]))
                    .collect()
            };
            check_samples_of(&u, &v, ts, texels).unwrap();
            check_samples_of(&v, &u, ts, texels).unwrap();
            checked += 1;
        }
    }
    assert_eq!(checked, ring.len() * specials.len());
}

/// The comparison itself catches a lane that differs by one unit in the last place.
#[test]
fn the_bitwise_comparison_catches_a_one_ulp_difference() {
    let (u, v) = ([0.3f32; LANES], [-0.2f32; LANES]);
    let row = taps_row(&u, &v, 16);
    let good = row.lane(0).unwrap();
    let shifted = taps(f32::from_bits(u[0].to_bits() + 1), v[0], 16).unwrap();
    assert_ne!(tap_bits(&good), tap_bits(&shifted));
    assert_eq!(tap_bits(&good), tap_bits(&taps(u[0], v[0], 16).unwrap()));
}

/// Compares every lane of `SupportQuad::row_spans` with `row_span` of its row, bit for bit
/// (`None` in the same lanes, the same bits of both ends elsewhere).
fn check_row_spans(quad: &SupportQuad, py: &[f32; ROW_LANES]) -> Result<(), String> {
    let lanes = quad.row_spans(py);
    for (l, got) in lanes.iter().enumerate() {
        let bits = |s: Option<(f32, f32)>| s.map(|(lo, hi)| (lo.to_bits(), hi.to_bits()));
        let want = quad.row_span(py[l]);
        if bits(*got) != bits(want) {
            return Err(format!("row {} of {quad:?}: lanes {got:?}, scalar {want:?}", py[l]));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(seeded_config(512))]

    /// Random quadrilaterals (convex or not, some with horizontal edges) and rows above, across
    /// and below them.
    #[test]
    fn row_spans_equal_the_scalar_row_span(
        corners in prop::array::uniform4((-60.0f32..60.0, -60.0f32..60.0)),
        flat in 0usize..6,
        margin in 0.01f32..0.5,
        first in -70.0f32..70.0,
        step in 0.1f32..3.0,
    ) {
        let mut corners = corners.map(|(x, y)| Vec2::new(x, y));
        // Cases 0-3: edge `flat` → `flat + 1` horizontal; 4, 5: none.
        if flat < 4 {
            corners[(flat + 1) % 4].y = corners[flat].y;
        }
        let quad = SupportQuad { corners, margin };
        let py: [f32; ROW_LANES] = std::array::from_fn(|l| first + step * l as f32);
        check_row_spans(&quad, &py).map_err(TestCaseError::fail)?;
        // Rows through the corners and at the band's edges, where the edge tests flip.
        for c in corners {
            let py: [f32; ROW_LANES] = std::array::from_fn(|l| c.y + (l as f32 - 3.5) * margin * 0.5);
            check_row_spans(&quad, &py).map_err(TestCaseError::fail)?;
        }
    }
}

/// Horizontal edges on the band's edges, non-finite rows and a degenerate (point) quad.
#[test]
fn row_spans_handle_flat_edges_and_non_finite_rows() {
    let square = SupportQuad {
        corners: [
            Vec2::new(0.0, 0.0),
            Vec2::new(10.0, 0.0),
            Vec2::new(10.0, 10.0),
            Vec2::new(0.0, 10.0),
        ],
        margin: 0.25,
    };
    let py = [
        -0.25,
        0.25,
        -0.3,
        10.25,
        f32::from_bits(10.25f32.to_bits() + 1),
        f32::NAN,
        f32::INFINITY,
        f32::from_bits((-0.25f32).to_bits() + 1),
    ];
    check_row_spans(&square, &py).unwrap();
    // Both branches are exercised: the band touching the flat edge from below gives a span,
    // the row just beyond it none.
    let spans = square.row_spans(&py);
    assert_eq!(spans[0], Some((-0.25, 10.25)));
    assert_eq!(spans[2], None);
    // Non-finite rows (never a pixel centre) need only agree with the scalar form, checked above.
    let point = SupportQuad {
        corners: [Vec2::splat(3.0); 4],
        margin: 0.01,
    };
    check_row_spans(&point, &[2.99, 3.0, 3.01, 3.02, -1.0, 3.005, 2.995, f32::NEG_INFINITY]).unwrap();
}

/// Taps made for sampling only carry no derivatives: differentiating them is refused (in debug
/// builds, where the check lives; the suite runs in them).
#[cfg(debug_assertions)]
#[test]
#[should_panic(expected = "taps for sampling only have no derivatives")]
fn sampling_only_taps_refuse_a_backward() {
    let (u, v) = ([0.1f32; LANES], [-0.2f32; LANES]);
    let texels = vec![[0.5f32; 4]; 16 * 16];
    let _ = sampling_taps_row(&u, &v, 16).vjp_rgba(0, &texels, [1.0; 4], |_, _| {});
}

/// `row_centres` is the per-lane `(first + l) as f32 + 0.5` bit for bit: near 0, on both sides
/// of the switch to the per-lane form below 2²³, where `f32` rounds the centres, and at the
/// top of the range.
#[test]
fn row_centres_equal_the_per_lane_centres() {
    let switch = (1u32 << 23) - LANES as u32;
    let firsts = (0..4096)
        .chain(switch - 4096..switch + 4096)
        .chain((1 << 24) - 64..(1 << 24) + 64)
        .chain(u32::MAX - 4096 - LANES as u32..=u32::MAX - LANES as u32);
    for first in firsts {
        let expected: [f32; LANES] = std::array::from_fn(|l| (first + l as u32) as f32 + 0.5);
        let got = row_centres(first);
        assert_eq!(got.map(f32::to_bits), expected.map(f32::to_bits), "first = {first}");
    }
}
