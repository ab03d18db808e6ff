//! The parallel texture step against the serial per-row loop.

use bbsplat::cpu::Simd;
use bbsplat::model::sigmoid;
use bbsplat::train::adam::{AdamGroup, AdamParams};
use bbsplat::train::regularise::chain_sigmoid;
use bbsplat::train::texture_step::{RowSelection, step_texture_group};

/// The parallel step equals the serial per-row loop (chain, `AdamGroup` step, activation)
/// bit for bit, dense and sparse, with a mask, for the colour and the alpha channels of RGBA
/// texels, on 2 and 1 threads, in the baseline and the AVX2 build; the other channels are left
/// alone. 37 texels a row: the vector loops run full registers and a remainder.
#[test]
fn matches_the_serial_row_loop_bit_for_bit() {
    let (rows, texels) = (150usize, 37usize);
    let mask: Vec<bool> = (0..texels).map(|k| k % 5 != 2).collect();
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % 20001) as f32 / 10000.0 - 1.0
    };
    let rgba0: Vec<[f32; 4]> = (0..rows * texels).map(|_| [0.0; 4].map(|_| next())).collect();
    let selected: Vec<bool> = (0..rows).map(|r| r % 3 != 1).collect();
    let hp = AdamParams::default();
    for channels in [0..3, 3..4] {
        let n = channels.len() * texels;
        let logits0: Vec<f32> = (0..rows * n).map(|_| 3.0 * next()).collect();
        // Planar gradients `[row][channel][texel]`, the same values as in the RGBA buffer.
        let grads_rgba0: Vec<[f32; 4]> = (0..rows * texels).map(|_| [0.0; 4].map(|_| next())).collect();
        let planar = |x: &[[f32; 4]]| -> Vec<f32> {
            (0..rows)
                .flat_map(|r| {
                    let channels = channels.clone();
                    channels.flat_map(move |ch| (0..texels).map(move |k| x[r * texels + k][ch]))
                })
                .collect()
        };
        let grads0 = planar(&grads_rgba0);
        let activate = |x: &[f32]| -> Vec<f32> {
            x.iter()
                .enumerate()
                .map(|(k, &x)| if mask[(k % n) % texels] { sigmoid(x) } else { 0.0 })
                .collect()
        };
        let row_mask: Vec<bool> = (0..n).map(|k| mask[k % texels]).collect();
        for dense in [true, false] {
            // Serial reference on planar rows: two steps.
            let mut group = AdamGroup::new(rows, n);
            let mut logits = logits0.clone();
            let mut act = activate(&logits);
            for _ in 0..2 {
                group.global_step += 1;
                for r in 0..rows {
                    if !dense && !selected[r] {
                        continue;
                    }
                    let span = r * n..(r + 1) * n;
                    let mut d = vec![0.0; n];
                    chain_sigmoid(&act[span.clone()], &grads0[span.clone()], Some(&row_mask), &mut d);
                    if dense {
                        let t = group.global_step;
                        group.step_row_global(r, &mut logits[span.clone()], &d, 0.01, &hp, t);
                    } else {
                        group.step_row(r, &mut logits[span.clone()], &d, 0.01, &hp);
                    }
                    act.splice(span.clone(), activate(&logits)[span].iter().copied());
                }
            }
            for (threads, baseline) in [(1, true), (2, true), (1, false), (2, false)] {
                let simd = if baseline { Simd::BASELINE } else { Simd::detect() };
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let mut g2 = AdamGroup::new(rows, n);
                let mut logits2 = logits0.clone();
                // The group's channels activated from the logits, the others arbitrary.
                let mut act2 = rgba0.clone();
                let planar_act = activate(&logits2);
                for r in 0..rows {
                    for (ci, ch) in channels.clone().enumerate() {
                        for k in 0..texels {
                            act2[r * texels + k][ch] = planar_act[r * n + ci * texels + k];
                        }
                    }
                }
                pool.install(|| {
                    for _ in 0..2 {
                        g2.global_step += 1;
                        let mut grads = grads_rgba0.clone();
                        let sel = if dense {
                            RowSelection::Dense
                        } else {
                            RowSelection::Sparse(&selected)
                        };
                        step_texture_group(
                            &mut g2,
                            &mut logits2,
                            &mut act2,
                            &mut grads,
                            channels.clone(),
                            Some(&mask),
                            sel,
                            None,
                            0.01,
                            &hp,
                            true,
                            simd,
                        );
                        for (g, g0) in grads.iter().zip(&grads_rgba0) {
                            for ch in 0..4 {
                                let want = if channels.contains(&ch) { 0.0 } else { g0[ch] };
                                assert_eq!(g[ch], want, "the group's gradients are consumed, no others");
                            }
                        }
                    }
                });
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                let tag = format!("channels {channels:?}, dense {dense}, {threads} threads, baseline {baseline}");
                assert_eq!(bits(&logits2), bits(&logits), "{tag}");
                assert_eq!(bits(&planar(&act2)), bits(&act), "{tag}");
                for (a, a0) in act2.iter().zip(&rgba0) {
                    for ch in (0..4).filter(|c| !channels.contains(c)) {
                        assert_eq!(a[ch], a0[ch], "{tag}: other channels untouched");
                    }
                }
                assert_eq!(bits(&g2.m), bits(&group.m));
                assert_eq!(bits(&g2.v), bits(&group.v));
                assert_eq!(g2.steps, group.steps);
            }
        }
    }
}

/// The texture step adding each row's regulariser gradient as it reads the row
/// (`added = Some(rows)`, what the trainer does with full textures) gives the bits of
/// `regularise` adding it in place first and the step adding nothing: logits, moments,
/// activated values, and the gradients left at zero; for both groups, dense and sparse, with a
/// mask, with both terms, with either alone, and with rows the texture term skips. The
/// gradients include `−0.0` and rows whose alpha offset is exactly zero (the texture term then
/// adds no alpha gradient). Measured: the step ignoring `added` fails this test.
#[test]
fn regulariser_gradients_added_as_read_match_adding_them_in_place() {
    let simd = Simd::detect();
    use bbsplat::train::regularise::{RowGradient, TextureTerm, regularise, regulariser_rows};
    let (rows, texels) = (12usize, 16usize);
    let mask: Vec<bool> = (0..texels).map(|k| k % 6 != 1).collect();
    let mut rng = bbsplat::rng::Rng::new(19);
    let mut next = || 2.0 * rng.uniform() - 1.0;
    let alpha0: Vec<f32> = (0..texels).map(|k| 0.25 + 0.01 * k as f32).collect();
    // Rows 0 and 1: alpha equal to the reference (offset exactly 0); the others random.
    let activated0: Vec<[f32; 4]> = (0..rows * texels)
        .map(|i| {
            let c = [0.5 + 0.4 * next(), 0.5 + 0.4 * next(), 0.5 + 0.4 * next()];
            let a = if i / texels < 2 {
                alpha0[i % texels]
            } else {
                0.5 + 0.4 * next()
            };
            [c[0], c[1], c[2], a]
        })
        .collect();
    let grads0: Vec<[f32; 4]> = (0..rows * texels)
        .map(|i| std::array::from_fn(|c| if (i + c) % 7 == 0 { -0.0 } else { 1e-3 * next() }))
        .collect();
    // Impacts: invisible, at and above the threshold (skipped by the texture term), and below.
    let impact: Vec<f32> = (0..rows)
        .map(|r| [0.0, 30.0, 500.0, 900.0, 120.0, 7.0][r % 6])
        .collect();
    let term = TextureTerm {
        alpha0: &alpha0,
        impact: &impact,
        threshold: 500.0,
        weight: 0.5,
    };
    let selected: Vec<bool> = (0..rows).map(|r| r % 4 != 3).collect();
    let hp = AdamParams::default();
    let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for (with_texture, with_opacity) in [(true, true), (true, false), (false, true)] {
        let (texture, opacity) = (with_texture.then_some(term), with_opacity.then_some(0.25));
        let mut added: Vec<RowGradient> = Vec::new();
        let values = regulariser_rows(&activated0, texels, texture, opacity, &mut added, simd);
        assert_eq!(added.len(), rows);
        assert!(added.iter().any(|a| a.texture.is_some()) == with_texture);
        for dense in [true, false] {
            let run = |in_place: bool| {
                let mut grads = grads0.clone();
                let mut activated = activated0.clone();
                if in_place {
                    let v = regularise(&activated0, texels, texture, opacity, &mut grads, simd);
                    assert_eq!(v, values, "the values do not depend on where the gradient goes");
                }
                let selection = if dense {
                    RowSelection::Dense
                } else {
                    RowSelection::Sparse(&selected)
                };
                let mut out = Vec::new();
                for (channels, group_mask) in [(3..4, Some(mask.as_slice())), (0..3, None)] {
                    let n = channels.len() * texels;
                    let mut group = AdamGroup::new(rows, n);
                    group.global_step = 1;
                    let mut logits: Vec<f32> = (0..rows * n).map(|k| (k % 11) as f32 * 0.3 - 1.5).collect();
                    step_texture_group(
                        &mut group,
                        &mut logits,
                        &mut activated,
                        &mut grads,
                        channels,
                        group_mask,
                        selection,
                        (!in_place).then_some(added.as_slice()),
                        0.01,
                        &hp,
                        true,
                        simd,
                    );
                    out.extend(bits(&logits));
                    out.extend(bits(&group.m));
                    out.extend(bits(&group.v));
                }
                out.extend(bits(activated.as_flattened()));
                assert!(
                    grads.iter().flatten().all(|&g| g == 0.0 && g.to_bits() == 0),
                    "consumed"
                );
                out
            };
            assert_eq!(
                run(false),
                run(true),
                "texture {with_texture}, opacity {with_opacity}, dense {dense}"
            );
        }
    }
}

/// The step's report: false when a logit it wrote is not finite (a NaN logit stays NaN through
/// Adam), true when the NaN lies in a row it did not step (sparse, unselected) or when it
/// stepped nothing (`update = false`).
#[test]
fn the_step_reports_the_finiteness_of_the_logits_it_wrote() {
    let simd = Simd::detect();
    let (rows, texels) = (8usize, 9usize);
    let hp = AdamParams::default();
    // The NaN sits in row 5: unselected in the first sparse case, selected in the second.
    let without_5: Vec<bool> = (0..rows).map(|r| r != 5).collect();
    let with_5: Vec<bool> = (0..rows).map(|r| r != 2).collect();
    for (selection, update, want) in [
        (RowSelection::Dense, true, false),
        (RowSelection::Sparse(&without_5), true, true),
        (RowSelection::Sparse(&with_5), true, false),
        (RowSelection::Dense, false, true),
    ] {
        let mut group = AdamGroup::new(rows, texels);
        group.global_step = 1;
        let mut logits = vec![0.5f32; rows * texels];
        logits[5 * texels + 4] = f32::NAN;
        let mut activated = vec![[0.5f32; 4]; rows * texels];
        let mut grads = vec![[1e-3f32; 4]; rows * texels];
        let finite = step_texture_group(
            &mut group,
            &mut logits,
            &mut activated,
            &mut grads,
            3..4,
            None,
            selection,
            None,
            0.01,
            &hp,
            update,
            simd,
        );
        assert_eq!(finite, want, "{selection:?}, update {update}");
    }
}

/// Both groups stepped chunk by chunk (`step_texture_pair`, what the trainer does) give the bits
/// of the two `step_texture_group` calls one after the other: logits, moments, step counts,
/// activated texels, the gradients left behind and each group's finiteness report. Dense and
/// sparse, with and without regulariser gradients, with the update on and off, on 1 and 2
/// threads, in the baseline and the AVX2 build. 150 rows: the last chunk is partial. One
/// alpha logit's gradient is NaN in the second case, so that one report is false and the
/// other true (a swapped or shared report fails).
#[test]
fn the_pair_step_equals_the_two_group_steps() {
    use bbsplat::train::regularise::RowGradient;
    use bbsplat::train::texture_step::{GroupStep, step_texture_pair};
    let (rows, texels) = (150usize, 37usize);
    let mask: Vec<bool> = (0..texels).map(|k| k % 5 != 2).collect();
    let mut state = 0x2545f4914f6cdd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % 20001) as f32 / 10000.0 - 1.0
    };
    let act0: Vec<[f32; 4]> = (0..rows * texels)
        .map(|_| [0.0; 4].map(|_| 0.5 + 0.4 * next()))
        .collect();
    let grads0: Vec<[f32; 4]> = (0..rows * texels).map(|_| [0.0; 4].map(|_| next())).collect();
    let alpha0: Vec<f32> = (0..rows * texels).map(|_| 3.0 * next()).collect();
    let colour0: Vec<f32> = (0..rows * 3 * texels).map(|_| 3.0 * next()).collect();
    let added: Vec<RowGradient> = (0..rows)
        .map(|r| RowGradient {
            texture: (r % 4 != 0).then(|| (1e-3 * next(), 1e-3 * next())),
            opacity: Some(1e-4),
        })
        .collect();
    let selected: Vec<bool> = (0..rows).map(|r| r % 3 != 1).collect();
    let hp = AdamParams::default();
    // Bits, with every NaN as one value: a NaN's sign and payload follow the operand order the
    // compiler picked, which differs between the two loops.
    let canonical = |v: f32| if v.is_nan() { u32::MAX } else { v.to_bits() };
    let bits = |x: &[f32]| x.iter().map(|&v| canonical(v)).collect::<Vec<_>>();
    let rgba_bits = |x: &[[f32; 4]]| x.iter().flat_map(|t| t.map(canonical)).collect::<Vec<_>>();
    let mut reports_seen = Vec::new();
    for nan in [false, true] {
        for (dense, with_added, update) in [
            (true, true, true),
            (true, false, true),
            (false, true, true),
            (true, true, false),
        ] {
            let mut grads_in = grads0.clone();
            if nan {
                grads_in[5 * texels + 3][3] = f32::NAN;
            }
            let selection = if dense {
                RowSelection::Dense
            } else {
                RowSelection::Sparse(&selected)
            };
            let added = with_added.then_some(added.as_slice());
            let run = |pair: bool, threads: usize, baseline: bool| {
                let simd = if baseline { Simd::BASELINE } else { Simd::detect() };
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let (mut a, mut c) = (AdamGroup::new(rows, texels), AdamGroup::new(rows, 3 * texels));
                let (mut al, mut cl) = (alpha0.clone(), colour0.clone());
                let (mut act, mut grads) = (act0.clone(), grads_in.clone());
                let mut reports = Vec::new();
                pool.install(|| {
                    for _ in 0..2 {
                        a.global_step += 1;
                        c.global_step += 1;
                        grads.copy_from_slice(&grads_in);
                        let report = if pair {
                            step_texture_pair(
                                GroupStep {
                                    group: &mut a,
                                    logits: &mut al,
                                    channels: 3..4,
                                    mask: Some(&mask),
                                    lr: 0.01,
                                },
                                GroupStep {
                                    group: &mut c,
                                    logits: &mut cl,
                                    channels: 0..3,
                                    mask: None,
                                    lr: 0.02,
                                },
                                &mut act,
                                &mut grads,
                                selection,
                                added,
                                &hp,
                                update,
                                simd,
                            )
                        } else {
                            let ra = step_texture_group(
                                &mut a,
                                &mut al,
                                &mut act,
                                &mut grads,
                                3..4,
                                Some(&mask),
                                selection,
                                added,
                                0.01,
                                &hp,
                                update,
                                simd,
                            );
                            let rc = step_texture_group(
                                &mut c,
                                &mut cl,
                                &mut act,
                                &mut grads,
                                0..3,
                                None,
                                selection,
                                added,
                                0.02,
                                &hp,
                                update,
                                simd,
                            );
                            [ra, rc]
                        };
                        reports.push(report);
                    }
                });
                (
                    bits(&al),
                    bits(&cl),
                    [bits(&a.m), bits(&a.v), bits(&c.m), bits(&c.v)],
                    (a.steps.clone(), c.steps.clone()),
                    rgba_bits(&act),
                    rgba_bits(&grads),
                    reports,
                )
            };
            let want = run(false, 1, true);
            for (threads, baseline) in [(1, true), (2, true), (1, false), (2, false)] {
                let got = run(true, threads, baseline);
                assert!(
                    got == want,
                    "nan {nan}, dense {dense}, added {with_added}, update {update}, {threads} threads, baseline {baseline}"
                );
            }
            reports_seen.push(want.6);
        }
    }
    // The NaN alpha gradient makes the alpha report false and leaves the colour report true.
    assert!(
        reports_seen
            .iter()
            .take(4)
            .all(|r| r.iter().all(|r| *r == [true, true]))
    );
    assert!(
        reports_seen
            .iter()
            .skip(4)
            .take(3)
            .all(|r| r.iter().all(|r| *r == [false, true]))
    );
}
