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
