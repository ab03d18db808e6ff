//! Scene benches: what a view decoded on demand costs a step (`scene::on_demand`): a miss
//! (decode the JPEG again, check its fingerprint), a hit, and the 8-bit-to-float conversion
//! every step makes anyway, on 1000×750 photos of the `large_capture` scene (JPEG quality 90,
//! as docs/scene.md measures).
//!
//! `cargo bench --features bench --bench scene -- --warm-up-time 1 --measurement-time 5`

use bbsplat::scene::{LoadOptions, load};
use bbsplat::train::TrainView;
use criterion::{Criterion, black_box, criterion_group, criterion_main};

fn on_demand(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("bbsplat-bench-scene-{}", std::process::id()));
    bbsplat::demo::export_capture(&dir, 2, 1000, 750).unwrap();
    let options = |image_memory| LoadOptions {
        test_every: 0,
        print_warnings: false,
        image_memory,
        ..LoadOptions::default()
    };
    // No cache: every use decodes. A cache of one image: every use hits.
    let uncached = load(&dir, &options(0)).unwrap();
    let cached = load(&dir, &options(1000 * 750 * 3)).unwrap();
    let mut group = c.benchmark_group("on_demand/1000x750");
    group.sample_size(20);
    group.bench_function("miss", |b| {
        b.iter(|| black_box(uncached.train[0].image.get().unwrap().as_bytes()[0]))
    });
    group.bench_function("hit", |b| {
        b.iter(|| black_box(cached.train[1].image.get().unwrap().as_bytes()[0]))
    });
    let in_memory = TrainView::from_view(&load(&dir, &options(u64::MAX)).unwrap().train[0]);
    let mut buffer = Vec::new();
    group.bench_function("u8_to_f32", |b| {
        b.iter(|| black_box(in_memory.rgb.as_f32(&mut buffer).unwrap()[0]))
    });
    let on_demand = TrainView::from_view(&uncached.train[0]);
    group.bench_function("miss_to_f32", |b| {
        b.iter(|| black_box(on_demand.rgb.as_f32(&mut buffer).unwrap()[0]))
    });
    group.finish();
    std::fs::remove_dir_all(&dir).ok();
}

criterion_group!(benches, on_demand);
criterion_main!(benches);
