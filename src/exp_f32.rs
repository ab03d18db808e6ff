//! `e^x` in `f32`, written so that a loop over it vectorises.
//!
//! The C library's `expf` is a call per value, so a loop of sigmoids (the texture step activates
//! a million texels a step) runs one value at a time. [`exp_f32`] is branch-free straight-line
//! arithmetic that the compiler turns into 4-lane (SSE2) or 8-lane (AVX2) code; every build gives
//! the same bits (no fused multiply-add: Rust never contracts a product and a sum by itself).
//!
//! Method: `x = n·ln 2 + r` with `n = round(x / ln 2)` and `|r| ≤ ln 2 / 2`, `ln 2` split in two
//! (Cody and Waite) so that `r` is exact to about 2⁻³²; `e^r` by its Taylor polynomial of degree 7
//! (truncation error below `r⁸/8! ≤ 5.2·10⁻⁹`, a twentieth of an ulp); `2ⁿ` put together from its
//! exponent bits. The error is at most 2 ulp against the exact value over the whole range
//! (measured worst 1.18 ulp, `tests/suite/exp_f32.rs`).
//!
//! Range: below [`MIN_ARG`] the result is 0 (the exact value there is under `2.7·10⁻³⁸`, close to
//! the smallest normal `f32`); above [`MAX_ARG`] it is `+∞`; NaN gives NaN.

/// Below this argument [`exp_f32`] returns 0.
pub const MIN_ARG: f32 = -86.5;
/// Above this argument [`exp_f32`] returns `+∞` (`ln(f32::MAX)` rounded down).
pub const MAX_ARG: f32 = 88.722_83;

/// `ln 2` in two parts: the high part has 9 significant bits, so `n · LN2_HI` is exact for
/// `|n| < 2¹⁵`.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
/// `1.5 · 2²³`: adding and subtracting it rounds an `f32` of magnitude below `2²²` to the nearest
/// integer (ties to even) without a rounding instruction (SSE2 has none).
const ROUND: f32 = 12_582_912.0;

/// `e^x` (see the module documentation for the method, range and accuracy).
///
/// ```
/// use bbsplat::exp_f32::exp_f32;
/// assert_eq!(exp_f32(0.0), 1.0);
/// assert!((exp_f32(1.0) - std::f32::consts::E).abs() <= 2.0 * f32::EPSILON * std::f32::consts::E);
/// assert_eq!(exp_f32(-100.0), 0.0);
/// assert_eq!(exp_f32(100.0), f32::INFINITY);
/// assert!(exp_f32(f32::NAN).is_nan());
/// ```
#[inline]
pub fn exp_f32(x: f32) -> f32 {
    let xc = x.clamp(MIN_ARG, MAX_ARG);
    let (n, n_int) = exponent(xc);
    let r = (xc - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    // `2ⁿ⁻¹ · 2` rather than `2ⁿ`: `n` reaches 128 just below MAX_ARG, whose `2ⁿ` has no `f32`
    // exponent; `n ≥ −125` above MIN_ARG keeps `2ⁿ⁻¹` normal. (`n` is integral and in range.)
    let half_scale = f32::from_bits((n_int.wrapping_add(126) as u32) << 23);
    let y = (p * half_scale) * 2.0;
    if x < MIN_ARG {
        0.0
    } else if x > MAX_ARG {
        f32::INFINITY
    } else {
        y
    }
}

/// `n = round(x·log₂e)` for a clamped argument `x`, by adding and subtracting [`ROUND`]: as a
/// float and as an integer. The integer is read from the bits of the rounded sum, not converted
/// from the float (Rust's saturating float-to-integer conversion is a long instruction
/// sequence): the sum lies in ROUND's binade, where one ulp is one unit, so its bits differ
/// from ROUND's by `n` exactly (checked against the conversion over the clamped range in
/// `tests/suite/exp_f32.rs`). For NaN the integer is arbitrary; `exp_f32` is NaN there anyway.
#[inline(always)]
pub(crate) fn exponent(x: f32) -> (f32, i32) {
    let shifted = x * std::f32::consts::LOG2_E + ROUND;
    let n = shifted - ROUND;
    (n, (shifted.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32))
}
