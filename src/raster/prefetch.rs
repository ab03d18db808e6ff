//! Cache prefetch hints: the rasterizer's reads are scattered (records, textures and gradient
//! rows of billboards in no screen order), so the tile passes ask for lines ahead of their use.
//! A prefetch never changes a value: it never faults, whatever the address, and reads nothing
//! the program can observe.

/// Hints the CPU to fetch the cache line holding `data[i]` (no effect on results).
#[inline(always)]
pub(crate) fn prefetch<T>(data: &[T], i: usize) {
    prefetch_ref(&data[i]);
}

/// Hints the CPU to fetch every cache line holding part of `*r` ([`prefetch_lines`]): an
/// 88-byte `Option<`[`Prepared`](super::preprocess::Prepared)`>` spans three lines when it starts past byte 40 of one (a
/// quarter of them in their array, whose records start at multiples of 8 bytes within a line),
/// and its first and last bytes alone would leave the middle line to a demand miss.
#[inline(always)]
pub(crate) fn prefetch_record<T>(r: &T) {
    prefetch_lines(std::slice::from_ref(r));
}

/// Hints the CPU to fetch every cache line holding part of `data` (no effect on results).
#[inline(always)]
pub(crate) fn prefetch_lines<T>(data: &[T]) {
    let Some(last) = size_of_val(data).checked_sub(1) else {
        return;
    };
    let start = data.as_ptr().cast::<u8>();
    prefetch_steps(data);
    // The last byte, whose line the steps miss when `data` does not start on a line boundary.
    prefetch_ptr(start.wrapping_add(last));
}

/// Hints the CPU to fetch the cache lines of `data`'s first byte and of every 64th byte after
/// it (no effect on results): every line when `data` starts on a line boundary, else all but
/// possibly the last ([`prefetch_lines`] adds it).
#[inline(always)]
pub(crate) fn prefetch_steps<T>(data: &[T]) {
    let start = data.as_ptr().cast::<u8>();
    for offset in (0..size_of_val(data)).step_by(64) {
        prefetch_ptr(start.wrapping_add(offset));
    }
}

/// Hints the CPU to fetch the cache line holding `*r` (no effect on results).
#[inline(always)]
pub(crate) fn prefetch_ref<T>(r: &T) {
    prefetch_ptr(std::ptr::from_ref(r).cast::<u8>());
}

/// Hints the CPU to fetch the cache lines holding the elements `indices` (a bilinear sample's
/// tap indices) of a per-texel array starting at `texels` (a texture, a texture-gradient row, the
/// backward's cell index), each line once: the two taps of a row share a line unless they
/// straddle a 64-byte boundary, and the taps come row by row, so comparing with the previous
/// tap's line finds every repeat. No effect on results; `texels` is never dereferenced.
#[inline(always)]
pub(crate) fn prefetch_taps<T>(texels: *const T, indices: &[u32]) {
    let mut last_line = usize::MAX;
    for &ix in indices {
        let p = texels.wrapping_add(ix as usize).cast::<u8>();
        if p as usize / 64 != last_line {
            last_line = p as usize / 64;
            prefetch_ptr(p);
        }
    }
}

/// Hints the CPU to fetch the cache line holding address `p` into the second-level cache
/// (`prefetcht1`), for a read further ahead than [`prefetch_ptr`]'s; `p` is never dereferenced.
#[inline(always)]
pub(crate) fn prefetch_ptr_l2(p: *const u8) {
    prefetch_with_hint::<L2_HINT>(p);
}

/// Hints the CPU to fetch the cache line holding address `p`; `p` is never dereferenced.
#[inline(always)]
pub(crate) fn prefetch_ptr(p: *const u8) {
    prefetch_with_hint::<L1_HINT>(p);
}

/// `_MM_HINT_T0`: into every level of cache.
const L1_HINT: i32 = 3;
/// `_MM_HINT_T1`: into the second level and beyond.
const L2_HINT: i32 = 2;
#[cfg(target_arch = "x86_64")]
const _: () = assert!(L1_HINT == std::arch::x86_64::_MM_HINT_T0 && L2_HINT == std::arch::x86_64::_MM_HINT_T1);

/// The prefetch of the line holding `p` with locality hint `HINT`; `p` is never dereferenced.
#[inline(always)]
fn prefetch_with_hint<const HINT: i32>(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint: it never faults, whatever the address, and reads nothing
    // the program can observe.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<HINT>(p.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
