//! Micro-benchmarks of the appearance stages' hot-loop pieces: bilinear taps and sampling
//! (1 and 3 channels) and their VJP, compositing per entry (forward and backward), SH
//! evaluation (degrees 0-3) and its VJP.
//!
//! `cargo bench --features bench --bench appearance -- --warm-up-time 1 --measurement-time 3`
//!
//! Inputs come from a ring of pre-generated random values (seeded), so that the branch
//! predictor does not see the same case every iteration.

use bbsplat::rng::Rng;
use bbsplat::stages::bilinear::{self, taps};
use bbsplat::stages::composite::{Blend, CompositeBackState, CompositeParams, CompositeState, Step};
use bbsplat::stages::sh::{SH_FLOATS, sh_colour, sh_colour_batch, sh_colour_vjp};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use std::hint::black_box;

const RING: usize = 1024;
const TS: usize = 16;

fn uniform(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.uniform_f64() as f32
}

fn bench_bilinear(c: &mut Criterion) {
    let mut rng = Rng::new(1);
    let uv: Vec<(f32, f32)> = (0..RING)
        .map(|_| (uniform(&mut rng, -1.0, 1.0), uniform(&mut rng, -1.0, 1.0)))
        .collect();
    let alpha: Vec<f32> = (0..TS * TS).map(|_| rng.uniform_f64() as f32).collect();
    let colour: Vec<f32> = (0..3 * TS * TS).map(|_| rng.uniform_f64() as f32).collect();
    let mut g = c.benchmark_group("bilinear");
    let mut i = 0;
    g.bench_function("taps", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            black_box(taps(black_box(u), black_box(v), TS))
        })
    });
    g.bench_function("taps+sample_1ch", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            black_box(t.sample_one(&alpha))
        })
    });
    g.bench_function("taps+sample_3ch", |b| {
        let mut out = [0.0f32; 3];
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            t.sample(&colour, 3, &mut out);
            black_box(out)
        })
    });
    g.bench_function("taps+sample_1ch+3ch", |b| {
        let mut out = [0.0f32; 3];
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            let a = t.sample_one(&alpha);
            t.sample(&colour, 3, &mut out);
            black_box((a, out))
        })
    });
    g.bench_function("sample_3ch_free_fn", |b| {
        let mut out = [0.0f32; 3];
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            bilinear::sample(&colour, TS, 3, black_box(u), black_box(v), &mut out);
            black_box(out)
        })
    });
    let mut d_alpha = vec![0.0f32; TS * TS];
    let mut d_colour = vec![0.0f32; 3 * TS * TS];
    g.bench_function("taps+vjp_1ch", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            black_box(t.accumulate_vjp_one(&alpha, 0.5, &mut d_alpha))
        })
    });
    g.bench_function("taps+vjp_3ch", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            black_box(t.accumulate_vjp(&colour, 3, &[0.5, -0.25, 0.125], &mut d_colour))
        })
    });
    // The rasterizer's path: one RGBA texture, all four channels per tap.
    let rgba: Vec<[f32; 4]> = (0..TS * TS)
        .map(|k| [colour[k], colour[TS * TS + k], colour[2 * TS * TS + k], alpha[k]])
        .collect();
    g.bench_function("taps+sample_rgba", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            black_box(t.sample_rgba(&rgba))
        })
    });
    let mut d_rgba = vec![[0.0f32; 4]; TS * TS];
    g.bench_function("taps+vjp_rgba", |b| {
        b.iter(|| {
            i = (i + 1) % RING;
            let (u, v) = uv[i];
            let t = taps(black_box(u), black_box(v), TS).unwrap();
            black_box(t.vjp_rgba(&rgba, [0.5, -0.25, 0.125, 0.5], |k, g| {
                let d = &mut d_rgba[k as usize];
                for c in 0..4 {
                    d[c] += g[c];
                }
            }))
        })
    });
    g.finish();
    black_box((d_alpha, d_colour, d_rgba));
}

fn bench_composite(c: &mut Criterion) {
    const N: usize = 32;
    const C: usize = 4;
    let mut rng = Rng::new(2);
    let p = CompositeParams::default();
    // Alphas small enough that the 32 entries never reach the transmittance stop.
    let alphas: Vec<f32> = (0..N).map(|_| uniform(&mut rng, 0.02, 0.2)).collect();
    let features: Vec<[f32; C]> = (0..N).map(|_| [0, 1, 2, 3].map(|_| rng.uniform_f64() as f32)).collect();
    let mut g = c.benchmark_group("composite");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("forward_32_entries", |b| {
        b.iter(|| {
            let mut s = CompositeState::<C>::new();
            for (a, f) in alphas.iter().zip(&features) {
                if let Step::Blend(bl) = s.step(black_box(*a), &p) {
                    s.blend(&bl, f);
                }
            }
            black_box(s.finish(&[0.0; C]))
        })
    });
    let mut s = CompositeState::<C>::new();
    let blends: Vec<Blend> = alphas
        .iter()
        .zip(&features)
        .filter_map(|(a, f)| match s.push(*a, f, &p) {
            Step::Blend(b) => Some(b),
            _ => None,
        })
        .collect();
    assert_eq!(blends.len(), N);
    let d_out = [0.5f32, -0.25, 0.125, 1.0];
    g.bench_function("backward_32_entries", |b| {
        b.iter(|| {
            let mut back = CompositeBackState::<C>::new(&[0.0; C]);
            let mut acc = 0.0f32;
            for (bl, f) in blends.iter().zip(&features).rev() {
                let e = back.pop(black_box(bl), f, &d_out, &p);
                acc += e.d_alpha + e.d_features[0];
            }
            black_box(acc)
        })
    });
    g.finish();
}

fn bench_sh(c: &mut Criterion) {
    let mut rng = Rng::new(3);
    let coeffs: Vec<f32> = (0..SH_FLOATS).map(|_| uniform(&mut rng, -0.3, 0.3)).collect();
    let pos: Vec<Vec3> = (0..RING)
        .map(|_| {
            Vec3::new(
                uniform(&mut rng, -5.0, 5.0),
                uniform(&mut rng, -5.0, 5.0),
                uniform(&mut rng, -5.0, 5.0),
            )
        })
        .collect();
    let centre = Vec3::new(0.1, 0.2, -8.0);
    let mut g = c.benchmark_group("sh");
    let mut i = 0;
    let mut d = vec![0.0f32; SH_FLOATS];
    for degree in 0..=3u32 {
        g.bench_function(format!("eval_deg{degree}"), |b| {
            b.iter(|| {
                i = (i + 1) % RING;
                black_box(sh_colour(black_box(degree), &coeffs, pos[i] - centre))
            })
        });
        // Four colours per iteration, interleaved (divide by 4 for the time per colour).
        g.bench_function(format!("eval_x4_deg{degree}"), |b| {
            b.iter(|| {
                i = (i + 4) % (RING - 4);
                let p = [pos[i], pos[i + 1], pos[i + 2], pos[i + 3]];
                black_box(sh_colour_batch(
                    black_box(degree),
                    [&coeffs[..]; 4],
                    p.map(|p| p - centre),
                ))
            })
        });
        g.bench_function(format!("vjp_deg{degree}"), |b| {
            b.iter(|| {
                i = (i + 1) % RING;
                black_box(sh_colour_vjp(
                    black_box(degree),
                    &coeffs,
                    pos[i] - centre,
                    Vec3::new(0.5, -0.25, 0.125),
                    &mut d,
                ))
            })
        });
    }
    g.finish();
    black_box(d);
}

criterion_group!(benches, bench_bilinear, bench_composite, bench_sh);
criterion_main!(benches);
