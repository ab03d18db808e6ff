//! The parallel texture step against the serial per-row loop.

use bbsplat::model::sigmoid;
use bbsplat::raster::lanes;
use bbsplat::train::adam::{AdamGroup, AdamParams};
use bbsplat::train::regularise::chain_sigmoid;
use bbsplat::train::texture_step::{RowSelection, step_texture_group};

/// The parallel step equals the serial per-row loop (chain, `AdamGroup` step, activation)
/// bit for bit, dense and sparse, with a mask, for the colour and the alpha channels of RGBA
/// texels, on 2 and 1 threads, in the baseline and the AVX2 build; the other channels are left
/// alone. 37 texels a row: the vector loops run full registers and a remainder.
#[test]
fn matches_the_serial_row_loop_bit_for_bit() {
    let _guard = crate::raster_lanes::SWITCH.lock().unwrap_or_else(|e| e.into_inner());
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
                lanes::force_baseline(baseline);
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
                            0.01,
                            &hp,
                            true,
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
                lanes::force_baseline(false);
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
