//! Tile binning: the parallel chunked binning against a plain reference, the depth sort key.

use bbsplat::raster::TILE_SIZE;
use bbsplat::raster::binning::{BinScratch, TileBins, bin, bin_into};
use bbsplat::raster::preprocess::Prepared;
use bbsplat::stages::splat_transform::SplatTransform;
use bbsplat::testing_internals::raster::{MIN_BIN_CHUNK, tile_rect, total_order_key};
use glam::Vec3;

/// Plain reference of [`bin`]: every tile scans every billboard in index order, then sorts
/// its list by (depth in total order, index); the billboard-major index walks the tiles in
/// order.
fn bin_reference(prepared: &[Option<Prepared>], width: u32, height: u32) -> TileBins {
    let (tiles_x, tiles_y) = (width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE));
    let mut bins = TileBins {
        tiles_x,
        tiles_y,
        tile_offsets: vec![0],
        ..TileBins::default()
    };
    let mut per_billboard: Vec<Vec<u32>> = vec![Vec::new(); prepared.len()];
    for ty in 0..tiles_y {
        for tx in 0..tiles_x {
            let mut list: Vec<u32> = (0..prepared.len() as u32)
                .filter(|&b| {
                    prepared[b as usize].as_ref().is_some_and(|p| {
                        let (lo, hi) = tile_rect(p);
                        (lo[0]..=hi[0]).contains(&tx) && (lo[1]..=hi[1]).contains(&ty)
                    })
                })
                .collect();
            let depth = |b: u32| prepared[b as usize].as_ref().map_or(0.0, |p| p.depth);
            list.sort_by(|&a, &b| depth(a).total_cmp(&depth(b)).then(a.cmp(&b)));
            for &b in &list {
                per_billboard[b as usize].push(bins.entries.len() as u32);
                bins.entries.push(b);
            }
            bins.tile_offsets.push(bins.entries.len() as u32);
        }
    }
    bins.billboard_offsets.push(0);
    for e in per_billboard {
        bins.billboard_entries.extend(e);
        bins.billboard_offsets.push(bins.billboard_entries.len() as u32);
    }
    bins
}

/// The parallel chunked binning equals the reference on scenes of one and of several
/// chunks (more than [`MIN_BIN_CHUNK`] billboards), with culled records, depth ties and
/// boxes spanning many tiles, and reused scratch gives the same result.
#[test]
fn bin_matches_the_plain_reference() {
    let mut rng = bbsplat::rng::Rng::new(0x9e37_79b9);
    let mut next = |m: u32| rng.below(u64::from(m)) as u32;
    let (mut bins, mut scratch) = (TileBins::default(), BinScratch::default());
    for &(n, width, height) in &[
        (0usize, 20u32, 20u32),
        (37, 33, 17),
        (2 * MIN_BIN_CHUNK + 123, 100, 70),
        (300, 256, 256),
    ] {
        let prepared: Vec<Option<Prepared>> = (0..n)
            .map(|_| {
                (next(5) != 0).then(|| {
                    let (x0, y0) = (next(width), next(height));
                    let (x1, y1) = ((x0 + next(40)).min(width - 1), (y0 + next(40)).min(height - 1));
                    Prepared {
                        transform: SplatTransform {
                            tu: Vec3::X,
                            tv: Vec3::Y,
                            tw: Vec3::Z,
                        },
                        normal: Vec3::Z,
                        plane_offset: -1.0,
                        // Few distinct depths: many ties, broken by index.
                        depth: 2.0 + next(8) as f32 * 0.25,
                        rgb: Vec3::ZERO,
                        sh_clamped: [false; 3],
                        normal_flipped: false,
                        pixel_min: [x0, y0],
                        pixel_max: [x1, y1],
                    }
                })
            })
            .collect();
        let want = bin_reference(&prepared, width, height);
        assert_eq!(bin(&prepared, width, height), want, "{n} billboards, {width}×{height}");
        bin_into(&prepared, width, height, &mut bins, &mut scratch);
        assert_eq!(bins, want, "{n} billboards, {width}×{height}, recycled storage");
    }
}

#[test]
fn total_order_key_sorts_like_total_cmp() {
    let mut xs = vec![
        0.2f32,
        -0.0,
        0.0,
        1e-30,
        -1e-30,
        3.5,
        -7.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MAX,
        f32::MIN_POSITIVE,
        100.25,
    ];
    let mut by_key = xs.clone();
    xs.sort_by(f32::total_cmp);
    by_key.sort_by_key(|&x| total_order_key(x));
    assert_eq!(
        xs.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        by_key.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
}
