//! The crate's random number generator: a stable stream, uniform draws and unbiased bounded integers.

use bbsplat::rng::*;

#[test]
fn stream_is_stable() {
    // Pinned values: changing the generator changes every seeded result in the crate.
    let mut r = Rng::new(0);
    let a = r.next_u64();
    let mut r2 = Rng::new(0);
    assert_eq!(a, r2.next_u64());
    let mut r3 = Rng::from_state(Rng::new(7).state());
    assert_eq!(r3.next_u64(), Rng::new(7).next_u64());
}

#[test]
fn uniform_in_range_and_below_unbiased() {
    let mut r = Rng::new(42);
    let mut counts = [0usize; 3];
    for _ in 0..30_000 {
        let u = r.uniform();
        assert!((0.0..1.0).contains(&u));
        counts[r.below(3) as usize] += 1;
    }
    for c in counts {
        assert!((9_400..10_600).contains(&c), "{counts:?}");
    }
}
