//! Loss benches at the training resolution (400×400 RGB).
//!
//! `cargo bench --features bench --bench loss -- --warm-up-time 1 --measurement-time 3`

use bbsplat::loss::l1::l1;
use bbsplat::loss::psnr::psnr;
use bbsplat::loss::ssim::{Padding, ssim, ssim_with_grad};
use bbsplat::loss::training_loss;
use bbsplat::rng::Rng;
use criterion::{Criterion, black_box, criterion_group, criterion_main};

const W: usize = 400;
const H: usize = 400;

fn images() -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng::new(7);
    let gt: Vec<f32> = (0..W * H * 3).map(|_| rng.uniform()).collect();
    let render = gt.iter().map(|v| v + rng.range(-0.1, 0.1)).collect();
    (render, gt)
}

fn losses(c: &mut Criterion) {
    let (render, gt) = images();
    let mut group = c.benchmark_group("loss_400x400x3");
    group.sample_size(20);
    group.bench_function("ssim_forward", |b| {
        b.iter(|| ssim(black_box(&render), &gt, W, H, 3, Padding::Same).unwrap())
    });
    group.bench_function("ssim_forward_backward", |b| {
        b.iter(|| ssim_with_grad(black_box(&render), &gt, W, H, 3, Padding::Same, 1.0).unwrap())
    });
    group.bench_function("training_loss", |b| {
        b.iter(|| training_loss(black_box(&render), &gt, W, H).unwrap())
    });
    group.bench_function("l1", |b| b.iter(|| l1(black_box(&render), &gt).unwrap()));
    group.bench_function("psnr", |b| b.iter(|| psnr(black_box(&render), &gt).unwrap()));
    group.finish();
}

criterion_group!(benches, losses);
criterion_main!(benches);
