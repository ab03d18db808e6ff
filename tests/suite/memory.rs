//! Large buffers and memory figures: allocation helpers, available memory, byte units.

use bbsplat::memory::*;

#[test]
fn large_and_small_vectors_hold_the_requested_values() {
    let n = 3 * HUGE_PAGE_MIN_BYTES / 4 + 17;
    let v = filled(n, 0.25f32);
    assert_eq!(v.len(), n);
    assert!(v.iter().all(|&x| x == 0.25));
    let mut w = with_capacity::<u32>(n);
    w.extend(0..n as u32);
    assert!(w.iter().enumerate().all(|(i, &x)| x == i as u32));
    assert_eq!(filled(0, 1u8), Vec::<u8>::new());
    assert!(with_capacity::<f64>(0).is_empty());
}

#[test]
fn available_memory_is_positive_where_known_and_bytes_print_in_units() {
    if let Some(b) = available_bytes() {
        assert!(b > 0);
    }
    assert_eq!(human_bytes(41_000_000_000), "41.0 GB");
    assert_eq!(human_bytes(511_200_000), "511.2 MB");
    // A 2 MiB file system is 2.1 MB, not the 3 MB that rounding up made of it.
    assert_eq!(human_bytes(2 << 20), "2.1 MB");
    assert_eq!(human_bytes(8192), "8.2 kB");
    assert_eq!(human_bytes(512), "512 bytes");
}
