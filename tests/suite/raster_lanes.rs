//! The rasterizer's choices made for speed alone (`bbsplat::cpu::Simd` and
//! `bbsplat::raster::lanes::TileWalk`, both in `RenderSettings`) give the same bits:
//! the instruction-set builds of its lane-wise tile loops (baseline SSE2, AVX2 + FMA, and the
//! forward's AVX-512 build, chosen at run time) and the two tile walks (billboard by billboard, pixel by pixel), in every
//! combination: every image, the per-billboard impact and every gradient, on trained-like
//! scenes (tens of blended billboards per pixel), the random benchmark scene (a pixel or two per
//! entry), and with the normal and distortion maps.
//!
//! On a CPU without AVX2 all renders take the baseline path and the comparison is trivially
//! equal, and without AVX-512 the last two builds are the same; the tests say so in their
//! output.

use bbsplat::billboards::{
    ActivatedBillboards, RandomSceneConfig, TrainedLikeConfig, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::camera::Camera;
use bbsplat::cpu::{Simd, SimdLevel};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::lanes::TileWalk;
use bbsplat::raster::{BackwardScratch, RenderGradients, RenderSettings, render, render_backward_with};
use bbsplat::rng::Rng;
/// The image gradients handed to the backward.
#[derive(Clone, Copy, Debug)]
enum Upstream {
    /// Fixed random values in [−0.5, 0.5).
    Noise,
    /// −0.0 everywhere: every texel gradient is then ±0.0, so a texel whose sign of zero an
    /// add changes shows in the bits (see `everything`).
    NegativeZero,
}

/// Every output bit of a render and its backward (with `scratch`) for the image gradients
/// `upstream`.
fn everything_with(
    scene: &ActivatedBillboards,
    cam: &Camera,
    settings: &RenderSettings,
    aux: bool,
    upstream: Upstream,
    scratch: &mut BackwardScratch,
) -> Vec<u32> {
    let set = scene.borrowed();
    let out = render(&set, cam, settings);
    let n = (cam.width * cam.height) as usize;
    let mut rng = Rng::new(7);
    let mut noise = |len: usize| {
        (0..len)
            .map(|_| match upstream {
                Upstream::Noise => rng.uniform() - 0.5,
                Upstream::NegativeZero => -0.0,
            })
            .collect::<Vec<f32>>()
    };
    let (rgb, alpha, depth, normal, distortion) = (noise(3 * n), noise(n), noise(n), noise(3 * n), noise(n));
    let grads_in = ImageGradients {
        rgb: &rgb,
        alpha: Some(&alpha),
        depth: Some(&depth),
        normal: aux.then_some(&normal[..]),
        distortion: aux.then_some(&distortion[..]),
        camera: false,
    };
    let mut grads = RenderGradients::zeros(scene.len(), scene.texture_size);
    // The texture rows start at −0.0, which only an add of −0.0 (or nothing) leaves as it is:
    // the AVX2 backward adds −0.0 for every tap that must not emit (outside the texture, or a
    // lane that did not blend), which the baseline never emits, so an add of +0.0 there would
    // turn such texels +0.0 in one build only.
    grads.textures.fill([-0.0; 4]);
    let touched = render_backward_with(&set, &out, &grads_in, &mut grads, scratch);
    let mut bits: Vec<u32> = [
        &out.rgb[..],
        &out.alpha,
        &out.depth,
        &out.median_depth,
        &out.normal,
        &out.distortion,
        &out.impact,
        &out.state.final_transmittance,
        &grads.sh,
    ]
    .iter()
    .flat_map(|v| v.iter().map(|x| x.to_bits()))
    .collect();
    bits.extend(grads.positions.iter().flat_map(|p| p.to_array().map(f32::to_bits)));
    bits.extend(grads.quaternions.iter().flat_map(|q| q.map(f32::to_bits)));
    bits.extend(grads.log_scales.iter().flat_map(|s| s.to_array().map(f32::to_bits)));
    bits.extend(grads.textures.iter().flat_map(|t| t.map(f32::to_bits)));
    bits.extend(grads.background.to_array().map(f32::to_bits));
    // Each tile's blended pairs (pixel, slot, transmittance in front), in one order whatever
    // the walk grouped them by.
    bits.extend(out.state.tiles.iter().flat_map(|tile| {
        tile.pairs_by_pixel()
            .into_iter()
            .flat_map(|(q, slot, t)| [q, slot, t.to_bits()])
    }));
    bits.extend(touched);
    bits.extend([
        out.stats.evaluated_pairs as u32,
        out.stats.blended_pairs as u32,
        out.stats.nan_alpha_pairs as u32,
    ]);
    bits
}

/// Renders under every combination of instruction set (baseline forced, or the widest the CPU
/// has) and tile walk (by each tile's size, every tile billboard by billboard, every tile pixel
/// by pixel); returns each combination's name and bits.
fn all_variants(
    scene: &ActivatedBillboards,
    cam: &Camera,
    settings: &RenderSettings,
    aux: bool,
) -> Vec<(String, Vec<u32>)> {
    all_variants_with(scene, cam, settings, aux, Upstream::Noise)
}

/// [`all_variants`] with the image gradients `upstream`.
fn all_variants_with(
    scene: &ActivatedBillboards,
    cam: &Camera,
    settings: &RenderSettings,
    aux: bool,
    upstream: Upstream,
) -> Vec<(String, Vec<u32>)> {
    let mut out = Vec::new();
    // The baseline build, the AVX2 build (AVX-512 ruled out), the widest build.
    for level in [SimdLevel::Baseline, SimdLevel::Avx2, SimdLevel::Avx512] {
        let simd = Simd::at_most(level);
        for walk in [TileWalk::Auto, TileWalk::ByEntry, TileWalk::ByPixel] {
            let name = format!("{:?} (asked {level:?}), {walk:?}", simd.level());
            let settings = RenderSettings {
                simd,
                tile_walk: walk,
                ..*settings
            };
            let scratch = &mut BackwardScratch::default();
            out.push((name, everything_with(scene, cam, &settings, aux, upstream, scratch)));
        }
    }
    println!("the widest build on this CPU: {:?}", Simd::detect().level());
    out
}

/// Every variant gives the bits of the first (baseline instruction set, automatic walk).
fn assert_all_equal(variants: &[(String, Vec<u32>)]) {
    let (first_name, first) = &variants[0];
    assert!(first.len() > 10_000);
    for (name, bits) in &variants[1..] {
        assert!(bits == first, "{name} differs from {first_name}");
    }
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_on_trained_like_scenes() {
    let cam = random_scene_camera(160, 128);
    for config in [
        TrainedLikeConfig::object(3000, 160, 128),
        TrainedLikeConfig::capture(3000, 160, 128),
    ] {
        let scene = trained_like_scene(&config);
        assert_all_equal(&all_variants(&scene, &cam, &RenderSettings::default(), false));
    }
}

/// Alphas above the clamp (`max_alpha`, where the exact clamp gradient is zero and the
/// reference's passes through), under both clamp gradients: a trained-like scene whose alpha
/// texels are scaled by 4 and capped at 1 (more than 5 % of the alpha texels above the clamp,
/// checked).
#[test]
fn every_build_and_walk_agree_bit_for_bit_above_the_alpha_clamp() {
    use bbsplat::stages::composite::{ClampGradient, CompositeParams};
    let cam = random_scene_camera(160, 128);
    let mut scene = trained_like_scene(&TrainedLikeConfig::object(3000, 160, 128));
    for texel in &mut scene.textures {
        texel[3] = (texel[3] * 4.0).min(1.0);
    }
    let clamped = scene.textures.iter().filter(|t| t[3] > 0.99).count();
    assert!(
        clamped * 20 > scene.textures.len(),
        "only {clamped} of {} alpha texels above the clamp",
        scene.textures.len()
    );
    for clamp_gradient in [ClampGradient::Exact, ClampGradient::PassThrough] {
        let settings = RenderSettings {
            composite: CompositeParams {
                clamp_gradient,
                ..CompositeParams::default()
            },
            ..RenderSettings::default()
        };
        assert_all_equal(&all_variants(&scene, &cam, &settings, false));
    }
}

/// With image gradients of −0.0 every texel gradient is ±0.0 (a texel's red, green and blue
/// gradients are −0.0, its alpha gradient +0.0), so a texel that received only zeros keeps the
/// sign of its row's start (−0.0, see `everything`) unless something adds +0.0 to it: the AVX2
/// backward's −0.0 adds for the taps that must not emit are checked here, where they are not
/// hidden by a nonzero contribution to the same texel. (Adding +0.0 there instead fails this
/// test: tried.)
#[test]
fn every_build_and_walk_agree_bit_for_bit_with_negative_zero_image_gradients() {
    let cam = random_scene_camera(160, 128);
    let scene = trained_like_scene(&TrainedLikeConfig::object(3000, 160, 128));
    let variants = all_variants_with(&scene, &cam, &RenderSettings::default(), false, Upstream::NegativeZero);
    assert_all_equal(&variants);
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_with_the_auxiliary_maps() {
    let cam = random_scene_camera(96, 80);
    let scene = trained_like_scene(&TrainedLikeConfig::object(1500, 96, 80));
    let settings = RenderSettings {
        distortion: true,
        ..RenderSettings::default()
    };
    assert_all_equal(&all_variants(&scene, &cam, &settings, true));
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_on_the_benchmark_scene() {
    let cam = random_scene_camera(128, 128);
    let scene = random_scene(&RandomSceneConfig::benchmark(8000, 128, 128));
    assert_all_equal(&all_variants(&scene, &cam, &RenderSettings::default(), false));
}

/// `render_backward_with` keeps its entry records, per-entry normal gradients and per-tile
/// texel lists in the caller's `BackwardScratch` for the next call; what an earlier, larger call
/// left there changes no bit. A small scene's bits (with and without the auxiliary maps, which
/// size the normal records) with a scratch that larger scenes used equal its bits with a fresh
/// scratch. (Leaving out the tile's reset of its records fails this test: tried. A texel
/// list left uncleared keeps correct spans and only grows; `texel_sums_match_the_sorting_reference`
/// catches that.)
#[test]
fn reused_backward_storage_changes_no_bit() {
    // Every output bit of a trained-like scene, with or without the auxiliary maps.
    let bits = |config: TrainedLikeConfig, aux: bool, scratch: &mut BackwardScratch| {
        let settings = RenderSettings {
            distortion: aux,
            ..RenderSettings::default()
        };
        let cam = random_scene_camera(config.width, config.height);
        everything_with(
            &trained_like_scene(&config),
            &cam,
            &settings,
            aux,
            Upstream::Noise,
            scratch,
        )
    };
    let small = |aux: bool, scratch: &mut BackwardScratch| bits(TrainedLikeConfig::object(800, 96, 80), aux, scratch);
    let large =
        |aux: bool, scratch: &mut BackwardScratch| bits(TrainedLikeConfig::capture(3000, 160, 128), aux, scratch);
    let fresh = [true, false].map(|aux| small(aux, &mut BackwardScratch::default()));
    let scratch = &mut BackwardScratch::default();
    large(true, scratch);
    let with_aux = small(true, scratch);
    large(false, scratch);
    let reused = [with_aux, small(false, scratch)];
    assert!(fresh[0].len() > 10_000);
    assert!(fresh[0] == reused[0], "with the auxiliary maps");
    assert!(fresh[1] == reused[1], "without them");
}

/// The AVX2 forward's explicit code can run: the CPU has AVX2 and FMA. On a CPU without them
/// the tests below check only that the AVX2 entry points refuse to run, and say so.
fn avx2_available() -> bool {
    let wide = Simd::detect().avx2_fma();
    println!("wide lanes (AVX2 + FMA) on this CPU: {wide}");
    wide
}

/// The AVX2 forward's lane-wise decision is `classify` bit for bit, on every threshold's edge:
/// raw alphas at, just below and just above `min_alpha` and `max_alpha`, 0, −0, 1, beyond,
/// NaN and ±∞, and transmittances at and around the one where `T·(1 − α)` meets
/// `min_transmittance`, under the default, reference and smooth parameters.
#[test]
fn avx2_forward_decision_equals_classify() {
    use bbsplat::stages::composite::{CompositeParams, Step, classify};
    use bbsplat::testing_internals::forward_avx2::classify_lanes;
    let wide = avx2_available();
    let mut rng = Rng::new(11);
    let mut compared = 0;
    for params in [
        CompositeParams::default(),
        CompositeParams::reference(),
        CompositeParams::smooth(),
    ] {
        let (lo, hi) = (params.min_alpha, params.max_alpha);
        let mut alphas = vec![
            0.0,
            -0.0,
            lo,
            lo.next_down(),
            lo.next_up(),
            hi,
            hi.next_down(),
            hi.next_up(),
            1.0,
            1.5,
            -1.0,
            1e-30,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        alphas.extend((0..40).map(|_| rng.uniform()));
        for &a in &alphas {
            // Transmittances around the stop threshold for this alpha, and ordinary ones.
            let clamped = if a > hi { hi } else { a };
            let edge = params.min_transmittance / (1.0 - clamped);
            let mut ts = vec![
                1.0,
                0.5,
                0.0,
                edge,
                edge.next_up(),
                edge.next_down(),
                params.min_transmittance,
            ];
            ts.extend((0..9).map(|_| rng.uniform()));
            for chunk in ts.chunks(8) {
                let t: [f32; 8] = std::array::from_fn(|l| chunk[l % chunk.len()]);
                let got = classify_lanes(&t, &[a; 8], &params);
                assert_eq!(got.is_some(), wide, "the AVX2 decision runs exactly when AVX2 is on");
                for (l, got) in got.iter().flat_map(|g| g.iter().enumerate()) {
                    let want = classify(t[l], a, &params);
                    let same = match (want, *got) {
                        (Step::Skip, Step::Skip) | (Step::Stop, Step::Stop) => true,
                        (Step::Blend(w), Step::Blend(g)) => {
                            [w.alpha, w.transmittance, w.weight, w.next_transmittance].map(f32::to_bits)
                                == [g.alpha, g.transmittance, g.weight, g.next_transmittance].map(f32::to_bits)
                                && w.clamped == g.clamped
                        }
                        _ => false,
                    };
                    assert!(same, "T {} a {a}: classify {want:?}, AVX2 {got:?}", t[l]);
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 1000 || !wide);
}

/// The AVX2 forward's packed push of a run's blended pairs appends, for every one of the 256
/// lane masks, exactly the pairs that pushing the set lanes one by one appends (pixel, column,
/// row, transmittance bits), keeps the pairs already there, and grows the list when it is full:
/// runs at the tile's first pixel and at its last row's last run, over lists of 0, 1 and 13
/// pairs. (Dropping lane 7 from the count, or reading the mask table mirrored, fails it: tried.)
#[test]
fn avx2_packed_pairs_equal_pushing_lane_by_lane() {
    use bbsplat::testing_internals::forward_avx2::push_pairs_lanes;
    let wide = avx2_available();
    let tile = bbsplat::raster::TILE_SIZE as usize;
    let mut rng = Rng::new(5);
    let mut compared = 0;
    for existing in [0usize, 1, 13] {
        let before: Vec<(u16, u8, u8, u32)> = (0..existing)
            .map(|i| (i as u16, i as u8, 1, rng.uniform().to_bits()))
            .collect();
        // The first run of the tile, and the last run of its last row.
        for (x0, y) in [(0usize, 0u8), (tile - 8, (tile - 1) as u8)] {
            let q0 = usize::from(y) * tile + x0;
            for bits in 0..256u32 {
                let fronts: [f32; 8] = std::array::from_fn(|_| rng.uniform());
                let got = push_pairs_lanes(&before, bits, (q0, x0, y), &fronts);
                assert_eq!(got.is_some(), wide, "the packed push runs exactly when AVX2 is on");
                let Some(got) = got else { continue };
                let mut want = before.clone();
                want.extend(
                    (0..8)
                        .filter(|l| bits >> l & 1 == 1)
                        .map(|l| ((q0 + l) as u16, (x0 + l) as u8, y, fronts[l].to_bits())),
                );
                assert_eq!(got, want, "mask {bits:08b} at ({x0}, {y}) after {existing} pairs");
                compared += 1;
            }
        }
    }
    println!("wide lanes: {wide}; {compared} masks compared");
    if wide {
        assert_eq!(compared, 3 * 2 * 256);
    }
}

/// The AVX2 forward's runs of an entry (`EntryRuns`) hold each pixel of its spans once, in
/// pixel order, at most eight per run, every part of a run along one row. A two-part run is
/// the rest of a row's span (fewer than eight pixels) followed by the first pixels of the next
/// non-empty row's, and its two windows of eight states (from the first part's first pixel,
/// and from `split` pixels before the second part's) share no pixel. Random spans, narrow and
/// wide, with empty rows; then a narrow billboard, whose rows share runs, and a wide one,
/// whose tails cannot take the next row's head. (Letting windows one pixel apart pair up
/// trips the forward's disjointness assertion in the raster tests: tried.)
#[cfg(target_arch = "x86_64")]
#[test]
fn avx2_forward_runs_cover_each_span_pixel_once_in_pixel_order() {
    use bbsplat::testing_internals::forward_avx2::entry_runs;
    let tw = bbsplat::raster::TILE_SIZE as usize;
    let mut rng = Rng::new(31);
    let (mut runs_seen, mut two_part) = (0, 0);
    for case in 0..3000 {
        let first_row = rng.below(tw as u64) as usize;
        let row_count = 1 + rng.below((tw - first_row) as u64) as usize;
        let widest = [1, 3, 7, 12, tw][case % 5];
        let rows: Vec<[u8; 2]> = (0..row_count)
            .map(|_| {
                if rng.uniform() < 0.1 {
                    return [9, 4];
                }
                let x0 = rng.below(tw as u64) as usize;
                let x1 = (x0 + rng.below(widest as u64) as usize).min(tw - 1);
                [x0 as u8, x1 as u8]
            })
            .collect();
        let want: Vec<usize> = rows
            .iter()
            .enumerate()
            .flat_map(|(i, &[x0, x1])| (usize::from(x0)..=usize::from(x1)).map(move |x| (first_row + i) * tw + x))
            .collect();
        let runs = entry_runs(&rows, first_row as u8, tw);
        let got: Vec<usize> = runs.iter().flat_map(|(pixels, _)| pixels.iter().copied()).collect();
        assert_eq!(got, want, "case {case}: every pixel once, in pixel order");
        for (pixels, two) in &runs {
            assert!((1..=8).contains(&pixels.len()), "case {case}: {pixels:?}");
            let breaks: Vec<usize> = (1..pixels.len()).filter(|&l| pixels[l] != pixels[l - 1] + 1).collect();
            let same_row = |part: &[usize]| part.iter().all(|&q| q / tw == part[0] / tw);
            if *two {
                assert_eq!(breaks.len(), 1, "case {case}: two parts {pixels:?}");
                let split = breaks[0];
                let (first, second) = pixels.split_at(split);
                assert!(same_row(first) && same_row(second) && second[0] / tw > first[0] / tw);
                assert!(
                    second[0] - split >= first[0] + 8,
                    "case {case}: windows overlap {pixels:?}"
                );
                // The first part ends its row's span: the next span pixel is the second part's.
                let at = want.iter().position(|&q| q == first[split - 1]).expect("a span pixel");
                assert_eq!(want[at + 1], second[0]);
                two_part += 1;
            } else {
                assert!(
                    breaks.is_empty() && same_row(pixels),
                    "case {case}: one part {pixels:?}"
                );
            }
            runs_seen += 1;
        }
    }
    println!("{runs_seen} runs, {two_part} of two parts");
    assert!(two_part > runs_seen / 10, "the random spans exercise two-part runs");
    // A billboard three pixels wide: two rows per run.
    let narrow = entry_runs(&[[10, 12]; 8], 0, tw);
    assert_eq!(narrow.len(), 4);
    assert!(narrow.iter().all(|(pixels, two)| *two && pixels.len() == 6));
    // Rows of 47 pixels: each tail's window would overlap the next row's, so it runs alone.
    let wide = entry_runs(&[[0, 46]; 3], 0, tw);
    assert_eq!(wide.len(), 3 * 6);
    assert!(wide.iter().all(|(_, two)| !*two));
}

/// The AVX2 forward's sample of eight lanes is `RowTaps::sample_rgba` bit for bit on every lane
/// with taps: coordinates across the texture, on its border ring and exactly on texel lines,
/// textures with NaN, ±∞ and −0 texels among random ones.
#[test]
fn avx2_forward_sample_equals_the_row_taps_sample() {
    use bbsplat::testing_internals::bilinear::sampling_taps_row;
    use bbsplat::testing_internals::forward_avx2::sample_rgba_lanes;
    let wide = avx2_available();
    let mut rng = Rng::new(12);
    let mut compared = 0;
    for ts in [2usize, 3, 8, 16] {
        let mut texture: Vec<[f32; 4]> = (0..ts * ts)
            .map(|_| [rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform()])
            .collect();
        for (k, special) in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0]
            .into_iter()
            .enumerate()
        {
            let t = rng.below((ts * ts) as u64) as usize;
            texture[t][k] = special;
        }
        let line = |i: usize| -1.0 + 2.0 * i as f32 / (ts - 1) as f32;
        for round in 0..200 {
            let coordinate = |rng: &mut Rng| match round % 3 {
                0 => rng.range(-1.4, 1.4),
                1 => line(rng.below(ts as u64) as usize),
                _ => rng.range(-1.0, 1.0),
            };
            let u: [f32; 8] = std::array::from_fn(|_| coordinate(&mut rng));
            let v: [f32; 8] = std::array::from_fn(|_| coordinate(&mut rng));
            let taps = sampling_taps_row(&u, &v, ts);
            let got = sample_rgba_lanes(&taps, &texture);
            assert_eq!(got.is_some(), wide, "the AVX2 sample runs exactly when AVX2 is on");
            for (l, got) in got.iter().flat_map(|g| g.iter().enumerate()) {
                if let Some(want) = taps.sample_rgba(l, &texture) {
                    assert_eq!(
                        want.map(f32::to_bits),
                        got.map(f32::to_bits),
                        "ts {ts}, (u, v) = ({}, {}): {want:?} against {got:?}",
                        u[l],
                        v[l],
                    );
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 4000 || !wide);
}
