//! Clap value parsers of the numeric flags whose size turns into memory or disk, and their
//! ranges: a value out of range is refused by clap, naming the flag and the range, before
//! anything is loaded. A leaf: the argument structs of every command use it.

/// Largest `render --orbit` (frames; an hour of video at 30 frames a second is 108 000).
pub const MAX_ORBIT_FRAMES: usize = 100_000;

/// Largest `mesh --compare-demo` (samples on each surface; 40 bytes each, twice).
pub const MAX_COMPARE_SAMPLES: usize = 10_000_000;

/// `render --frame-ms` range: a GIF stores delays in hundredths of a second, at most 65 535.
pub const FRAME_MS_RANGE: std::ops::RangeInclusive<u32> = 10..=655_350;

/// A whole number in `MIN..=MAX`, for clap's `value_parser` (the error names the range).
pub fn count_between<const MIN: usize, const MAX: usize>(text: &str) -> Result<usize, String> {
    match text.parse::<u128>() {
        Ok(n) if (MIN as u128..=MAX as u128).contains(&n) => Ok(n as usize),
        Ok(n) => Err(format!("{n} is not between {MIN} and {MAX}")),
        Err(e) => Err(format!("{text:?} is not a whole number: {e}")),
    }
}

/// `render --frame-ms`: [`FRAME_MS_RANGE`], a multiple of 10 (the GIF's unit) or refused.
pub fn frame_ms(text: &str) -> Result<u32, String> {
    let (lo, hi) = (*FRAME_MS_RANGE.start(), *FRAME_MS_RANGE.end());
    match text.parse::<u64>() {
        Ok(n) if n % 10 != 0 => Err(format!(
            "{n} is not a multiple of 10 (a GIF stores hundredths of a second)"
        )),
        Ok(n) if (lo as u64..=hi as u64).contains(&n) => Ok(n as u32),
        Ok(n) => Err(format!(
            "{n} is not between {lo} and {hi} (a GIF's longest frame is 655.35 s)"
        )),
        Err(e) => Err(format!("{text:?} is not a whole number: {e}")),
    }
}

/// A size in bytes written as a whole number with a unit: `K`, `M` or `G` (powers of 1024;
/// `MiB`-style suffixes and a trailing `B` accepted), e.g. `512M`, `2G`; a bare number is
/// MiB. At most 1 TiB.
pub fn byte_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    let trimmed = upper.trim_end_matches('B').trim_end_matches('I');
    let digits = trimmed.trim_end_matches(['K', 'M', 'G']);
    let unit: u64 = match &trimmed[digits.len()..] {
        "K" => 1 << 10,
        "" | "M" => 1 << 20,
        "G" => 1 << 30,
        other => return Err(format!("{text:?}: unknown unit {other:?} (use K, M or G, e.g. 2G)")),
    };
    let n: u64 = digits
        .trim()
        .parse()
        .map_err(|e| format!("{text:?} is not a whole number with a unit (e.g. 512M, 2G): {e}"))?;
    match n.checked_mul(unit) {
        Some(bytes) if bytes <= 1 << 40 => Ok(bytes),
        _ => Err(format!("{text:?} is more than 1 TiB")),
    }
}

#[cfg(test)]
mod tests {
    use super::byte_size;

    #[test]
    fn sizes_with_units() {
        assert_eq!(byte_size("2G"), Ok(2 << 30));
        // `--image-memory`'s default is the library's.
        assert_eq!(byte_size("2G"), Ok(bbsplat::scene::on_demand::DEFAULT_IMAGE_MEMORY));
        assert_eq!(byte_size("512m"), Ok(512 << 20));
        assert_eq!(byte_size("300"), Ok(300 << 20));
        assert_eq!(byte_size("64KiB"), Ok(64 << 10));
        assert_eq!(byte_size("1GB"), Ok(1 << 30));
        assert_eq!(byte_size("0"), Ok(0));
        assert!(byte_size("2T").is_err());
        assert!(byte_size("2048G").is_err());
        assert!(byte_size("lots").is_err());
        assert!(byte_size("-1G").is_err());
    }
}
