//! Allocation of the large per-billboard arrays (textures, their gradients and optimiser
//! moments) with a transparent-huge-page hint, and the reset of recycled buffers (`refill`).
//!
//! The rasterizer reads and writes these arrays at scattered rows: a 16×16 texture is 1 KiB per
//! channel, so every billboard a pixel touches is a different 4 KiB page, and at 50 000
//! billboards the textures alone span 200 MiB, far more than the TLB covers. Backing them with
//! 2 MiB pages removes most TLB misses. On Linux, when the kernel's transparent huge pages are in
//! `madvise` mode (`/sys/kernel/mm/transparent_hugepage/enabled`), a region gets them only if
//! the process asks with `madvise(MADV_HUGEPAGE)` *before* its pages are first touched; the
//! helpers here allocate, ask, and only then write. Elsewhere, or when the kernel refuses,
//! they are plain allocations: the hint never changes a value, only where it lives.

/// Arrays smaller than this are allocated without the hint (2 MiB pages would not pay off).
pub const HUGE_PAGE_MIN_BYTES: usize = 4 << 20;

/// Size of a transparent huge page on x86-64 and most aarch64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// An empty vector with room for `capacity` values, its storage hinted to use huge pages when
/// it is at least [`HUGE_PAGE_MIN_BYTES`] long. Fill it without reallocating (`extend`, `push`
/// up to the capacity) to keep the hint.
///
/// ```
/// let mut v = bbsplat::memory::with_capacity::<f32>(4);
/// v.extend([1.0, 2.0]);
/// assert!(v.capacity() >= 4);
/// ```
pub fn with_capacity<T>(capacity: usize) -> Vec<T> {
    let v = Vec::with_capacity(capacity);
    advise(&v);
    v
}

/// A vector of `len` copies of `value`, its storage hinted to use huge pages (see
/// [`with_capacity`]).
///
/// ```
/// let v = bbsplat::memory::filled(3, 0.5f32);
/// assert_eq!(v, vec![0.5; 3]);
/// ```
pub fn filled<T: Clone>(len: usize, value: T) -> Vec<T> {
    let mut v = with_capacity(len);
    v.resize(len, value);
    v
}

/// Asks the kernel to back the 2 MiB-aligned part of `v`'s capacity with huge pages.
fn advise<T>(v: &Vec<T>) {
    let bytes = v.capacity() * size_of::<T>();
    if bytes < HUGE_PAGE_MIN_BYTES {
        return;
    }
    let start = (v.as_ptr() as usize).next_multiple_of(HUGE_PAGE);
    let end = (v.as_ptr() as usize + bytes) / HUGE_PAGE * HUGE_PAGE;
    if end > start {
        advise_range(start, end - start);
    }
}

#[cfg(target_os = "linux")]
fn advise_range(start: usize, len: usize) {
    // SAFETY: `start..start + len` lies inside one live allocation owned by the caller's vector
    // and is page-aligned; MADV_HUGEPAGE only changes how the kernel backs those pages, never
    // their contents, and a refusal (EINVAL when THP is compiled out) is ignored.
    unsafe {
        libc::madvise(start as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_range(_start: usize, _len: usize) {}

/// `v` resized to `len`, keeping the values it holds (only new slots get `value`): for
/// recycled buffers whose every value the caller then overwrites, so that resetting them would
/// be a wasted pass over memory.
pub(crate) fn resize_for_overwrite<T: Clone>(v: &mut Vec<T>, len: usize, value: T) -> &mut [T] {
    v.truncate(len);
    v.resize(len, value);
    v
}

/// `v` cleared and refilled with `len` copies of `value`, keeping its storage (no allocation
/// when its capacity suffices): how the rasterizer's recycled buffers are reset.
pub(crate) fn refill<T: Clone>(v: &mut Vec<T>, len: usize, value: T) -> &mut [T] {
    v.clear();
    v.resize(len, value);
    v
}

/// Memory the system can still give this process without swapping, in bytes: Linux's
/// `MemAvailable` (`/proc/meminfo`), further bounded by the cgroup limit of the process when one
/// is set (`/sys/fs/cgroup/memory.max` minus `memory.current`). `None` where neither can be read
/// (other systems): callers then skip their memory checks.
pub fn available_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kib: u64 = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    let mut available = kib.saturating_mul(1024);
    let read = |f: &str| std::fs::read_to_string(f).ok()?.trim().parse::<u64>().ok();
    if let (Some(max), Some(current)) = (read("/sys/fs/cgroup/memory.max"), read("/sys/fs/cgroup/memory.current")) {
        available = available.min(max.saturating_sub(current));
    }
    Some(available)
}

/// A byte count for messages, in decimal units rounded to the nearest tenth, never up to the
/// next whole unit (a free-space figure must not look larger than it is): `"41.0 GB"`,
/// `"511.2 MB"`, `"8.2 kB"`, `"512 bytes"`.
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.1} kB", b / 1e3)
    } else {
        format!("{bytes} bytes")
    }
}
