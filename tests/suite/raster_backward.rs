//! The backward pass's texel-gradient accumulator against a sorting reference.

use bbsplat::testing_internals::raster::TexelSums;

/// Plain reference of the texel-gradient accumulator: stable sort of the contributions `(slot, texel, g)` by
/// (slot, texel), then each run of equal keys summed in order. Texels come out sorted within a
/// slot.
fn texel_sums_reference(log: &[(u32, u32, [f32; 4])], slots: usize) -> (Vec<u32>, Vec<(u32, [f32; 4])>) {
    let mut log = log.to_vec();
    log.sort_by_key(|&(slot, texel, _)| (slot, texel));
    let mut counts = vec![0u32; slots + 1];
    let mut out: Vec<(u32, [f32; 4])> = Vec::with_capacity(log.len());
    let mut run = 0;
    while run < log.len() {
        let (slot, texel, mut sum) = log[run];
        let mut next = run + 1;
        while next < log.len() && log[next].0 == slot && log[next].1 == texel {
            for c in 0..4 {
                sum[c] += log[next].2[c];
            }
            next += 1;
        }
        out.push((texel, sum));
        counts[slot as usize + 1] += 1;
        run = next;
    }
    for k in 0..slots {
        counts[k + 1] += counts[k];
    }
    (counts, out)
}

/// A cell's first contribution is assigned, not added to 0: a lone `−0.0` stays `−0.0`
/// (`0.0 + −0.0` would be `+0.0`), as in the sorting reference.
#[test]
fn texel_sums_keep_a_lone_negative_zero() {
    let mut sums = TexelSums::default();
    sums.start(2, 4);
    sums.add(1, 3, [-0.0, 1.0, -0.0, 2.0]);
    let (offsets, out) = sums.finish(2);
    assert_eq!(offsets, [0, 0, 1]);
    let bits = out[0].1.map(f32::to_bits);
    assert_eq!(
        (out[0].0, bits),
        (
            3,
            [
                (-0.0f32).to_bits(),
                1.0f32.to_bits(),
                (-0.0f32).to_bits(),
                2.0f32.to_bits()
            ]
        )
    );
    let log = [(1u32, 3u32, [-0.0f32, 1.0, -0.0, 2.0])];
    assert_eq!(texel_sums_reference(&log, 2).1[0].1.map(f32::to_bits), bits);
}

/// The accumulator gives, slot by slot, the same (texel, sum) set as the sort-based
/// reference, bit for bit.
#[test]
fn texel_sums_match_the_sorting_reference() {
    let mut state = 0x2545f4914f6cdd1du64;
    let mut next = |m: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state % m
    };
    // One accumulator across all cases: it must come back clean from every tile.
    let mut sums = TexelSums::default();
    for &(slots, texels, len) in &[(1usize, 4usize, 0usize), (3, 4, 50), (17, 256, 400), (40, 16, 2000)] {
        let log: Vec<(u32, u32, [f32; 4])> = (0..len)
            .map(|_| {
                let g = [0; 4].map(|_| (next(2001) as f32 - 1000.0) * 1.37e-3);
                (next(slots as u64) as u32, next(texels as u64) as u32, g)
            })
            .collect();
        sums.start(slots, texels);
        for &(slot, texel, g) in &log {
            sums.add(slot, texel, g);
        }
        let (offsets, out) = sums.finish(slots);
        assert!(sums.is_clean());
        let (ref_offsets, ref_out) = texel_sums_reference(&log, slots);
        assert_eq!(offsets, ref_offsets);
        for k in 0..slots {
            let r = offsets[k] as usize..offsets[k + 1] as usize;
            let mut got: Vec<(u32, [u32; 4])> = out[r.clone()].iter().map(|&(t, g)| (t, g.map(f32::to_bits))).collect();
            got.sort_by_key(|e| e.0);
            let want: Vec<(u32, [u32; 4])> = ref_out[r].iter().map(|&(t, g)| (t, g.map(f32::to_bits))).collect();
            assert_eq!(got, want, "slot {k}");
        }
    }
}
