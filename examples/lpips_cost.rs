//! Wall-clock seconds of one LPIPS distance (`bbsplat::lpips`) of a `SIDE × SIDE` image pair,
//! for both networks: the figure of docs/lpips.md.
//!
//! ```text
//! python3 tools/lpips_weights.py   # once
//! cargo run --release --features examples --example lpips_cost -- [SIDE (400)] [REPEATS (3)]
//! ```
//! The images are a deterministic pattern and the same pattern with noise; the time of each
//! repeat is printed, then the median.

use bbsplat::lpips::{Lpips, Variant};
use bbsplat::rng::Rng;
use std::process::ExitCode;
use std::time::Instant;

fn run() -> Result<(), String> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().map_err(|_| format!("not a count: {a}")))
        .collect::<Result<_, _>>()?;
    let side = args.first().copied().unwrap_or(400);
    let repeats = args.get(1).copied().unwrap_or(3).max(1);
    let mut rng = Rng::new(1);
    let first: Vec<f32> = (0..side * side * 3)
        .map(|i| 0.5 + 0.4 * ((i % (side * 3)) as f32 * 0.01).sin() * ((i / (side * 3)) as f32 * 0.02).cos())
        .collect();
    let second: Vec<f32> = first
        .iter()
        .map(|v| (v + 0.05 * rng.normal()).clamp(0.0, 1.0))
        .collect();
    println!("{side}×{side} pair, {} rayon threads", rayon::current_num_threads());
    for variant in [Variant::Vgg, Variant::Alex] {
        let net = Lpips::load_cached(variant).map_err(|e| e.to_string())?;
        let mut seconds: Vec<f64> = (0..repeats)
            .map(|_| {
                let start = Instant::now();
                let d = net.distance(&first, &second, side, side).expect("sizes match");
                let s = start.elapsed().as_secs_f64();
                println!("  {variant}: LPIPS {d:.5} in {s:.3} s");
                s
            })
            .collect();
        seconds.sort_by(f64::total_cmp);
        println!("{variant}: median {:.3} s per pair", seconds[seconds.len() / 2]);
    }
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lpips_cost: {e}");
            ExitCode::FAILURE
        }
    }
}
