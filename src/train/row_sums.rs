//! The f64 sums of one billboard's activated texture row that the regularisers read, each equal
//! bit for bit to its sum in texel order, but computed in any order when no order can change
//! them.
//!
//! The regularisers ([`mod@super::regularise`]) sum a row's values in f64 in a fixed order: the
//! colour channels (r over the texels, then g, then b), the alpha channel, and the alpha minus a
//! reference alpha `alpha0`. In texel order each sum is one chain of dependent additions
//! (1280 of them for a 16×16 row), so the regulariser pass waited on the adder's latency, not on
//! memory.
//!
//! **When the order cannot matter.** Let `n` bound the number of values in a sum (here `3·T`,
//! `T` texels a row) and `L = ⌈log₂ n⌉`. If every value is `+0.0` or lies in `[τ, 1]` with
//! `τ = 2^(L − 30)`, then every value is a whole multiple of `2^(L − 53)` (an `f32` at or above
//! `2^e` is a multiple of `2^(e − 23)`), so is every difference of two values and every partial
//! sum of them; and every partial sum has magnitude at most `n ≤ 2^L`. An f64 holds every
//! multiple of `2^(L − 53)` up to `2^L` exactly, so every addition of every order is exact and
//! all orders give the one exact sum. A zero result is `+0.0` in every order too: no value
//! carries a sign bit, and `x + (−x)` is `+0.0`. [`exact_in_any_order`] checks that condition
//! (NaN, infinities, negative values, `−0.0`, subnormals and values in `(0, τ)` fail it); the fast
//! path then sums the four channels of a texel at once (one f64 lane each, two texels in flight),
//! and any other row takes the texel-order sums. The alpha offset is there `Σα − Σα₀`: both sums
//! are exact, so their difference is the exact `Σ(α − α₀)` (a multiple of the same unit, no
//! larger than `2^L`), which the texel order gives too.
//!
//! At `T = 256` the threshold is `τ = 2⁻²⁰ ≈ 9.5·10⁻⁷`: a sigmoid below it needs a logit below
//! −13.9. Every row of a 30-minute lego model (20 000 rows) and of a beer_colmap model (10 886
//! rows) meets the condition. The row loop is compiled for AVX2 at run time like the tile loops
//! (`crate::raster::lanes`); the sums are the same bits in either build.

/// A row's sums (all in f64, see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowSums {
    /// `Σ_c Σ_k texel[k][c]` over the colour channels `c = 0, 1, 2` (0 without `alpha0`).
    pub colour: f64,
    /// `Σ_k texel[k][3]`.
    pub alpha: f64,
    /// `Σ_k (texel[k][3] − alpha0[k])`, each difference in f64 (0 without `alpha0`).
    pub alpha_offset: f64,
}

/// The sums of the row `texels` in texel order: the definition (the colour sum channel after
/// channel, each over the texels in order; the others over the texels in order). With `alpha0
/// = None` only [`RowSums::alpha`] is summed.
///
/// # Panics
/// When `alpha0` does not hold one value per texel.
pub fn row_sums_in_order(texels: &[[f32; 4]], alpha0: Option<&[f32]>) -> RowSums {
    let alpha = texels.iter().map(|x| x[3] as f64).sum::<f64>();
    let Some(alpha0) = alpha0 else {
        return RowSums {
            alpha,
            ..RowSums::default()
        };
    };
    assert_eq!(alpha0.len(), texels.len(), "one reference alpha per texel");
    RowSums {
        colour: (0..3)
            .flat_map(|c| texels.iter().map(move |x| x[c] as f64))
            .sum::<f64>(),
        alpha,
        alpha_offset: texels
            .iter()
            .zip(alpha0)
            .map(|(x, &x0)| x[3] as f64 - x0 as f64)
            .sum::<f64>(),
    }
}

/// [`row_sums_in_order`], bit for bit: in vector lanes when [`exact_in_any_order`] holds,
/// else in texel order; in the AVX2 build when `simd` has it (the same bits).
///
/// # Panics
/// As [`row_sums_in_order`].
pub fn row_sums(texels: &[[f32; 4]], alpha0: Option<&[f32]>, simd: crate::cpu::Simd) -> RowSums {
    #[cfg(target_arch = "x86_64")]
    if simd.avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (a `Simd` at that level exists only on such a CPU).
        return unsafe { row_sums_avx2(texels, alpha0) };
    }
    row_sums_body(texels, alpha0)
}

/// [`row_sums_body`] compiled for AVX2 (the same operations: conversions and additions, exact
/// on the fast path, so the same bits).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn row_sums_avx2(texels: &[[f32; 4]], alpha0: Option<&[f32]>) -> RowSums {
    row_sums_body(texels, alpha0)
}

/// The body of [`row_sums`], inlined into each instruction-set variant.
#[inline(always)]
fn row_sums_body(texels: &[[f32; 4]], alpha0: Option<&[f32]>) -> RowSums {
    if !exact_in_any_order(texels, alpha0) {
        return row_sums_in_order(texels, alpha0);
    }
    // Every order gives the same exact sums: all four channels of a texel at once (one f64
    // lane each), two accumulators for the adder's latency.
    let mut lanes = [[0.0f64; 4]; 2];
    let (pairs, last) = texels.as_chunks::<2>();
    for [x0, x1] in pairs {
        for c in 0..4 {
            lanes[0][c] += x0[c] as f64;
            lanes[1][c] += x1[c] as f64;
        }
    }
    for x in last {
        for c in 0..4 {
            lanes[0][c] += x[c] as f64;
        }
    }
    let channel = |c: usize| lanes[0][c] + lanes[1][c];
    let alpha = channel(3);
    let Some(alpha0) = alpha0 else {
        return RowSums {
            alpha,
            ..RowSums::default()
        };
    };
    // `Σ (α − α₀)` is `Σ α − Σ α₀`: both sums are exact, and so is their difference (a multiple of
    // the same unit, no larger than the bound of the module docs).
    let (chunks, rest) = alpha0.as_chunks::<8>();
    let mut reference = [0.0f64; 8];
    for chunk in chunks {
        for (r, &x) in reference.iter_mut().zip(chunk) {
            *r += x as f64;
        }
    }
    let reference = rest.iter().fold(reference.iter().sum::<f64>(), |s, &x| s + x as f64);
    RowSums {
        colour: channel(0) + channel(1) + channel(2),
        alpha,
        alpha_offset: alpha - reference,
    }
}

/// True when every value the sums of [`row_sums`] read (the alpha channel of `texels`; with
/// `alpha0`, also their colour channels and `alpha0`) is `+0.0` or lies in `[τ, 1]` with
/// `τ = 2^(⌈log₂(3·T)⌉ − 30)`: every order of every sum of [`RowSums`] is then exact (module
/// docs). False for rows of more than `2²⁰` texels (not a texture this crate makes).
///
/// # Panics
/// When `alpha0` does not hold one value per texel.
#[inline(always)]
pub fn exact_in_any_order(texels: &[[f32; 4]], alpha0: Option<&[f32]>) -> bool {
    assert!(
        alpha0.is_none_or(|a| a.len() == texels.len()),
        "one reference alpha per texel"
    );
    let values = 3 * texels.len().max(1);
    if values > 3 << 20 {
        return false;
    }
    let log2 = values.next_power_of_two().trailing_zeros() as i32;
    let low = 2f32.powi(log2 - 30).to_bits();
    let high = 1f32.to_bits();
    // On the bits: a positive `f32`'s bits grow with its value; a sign bit, an infinity or a
    // NaN puts them above 1.0's.
    // `low ≤ b ≤ high` as one unsigned comparison (`b − low` wraps above `high − low` below).
    let span = high - low;
    let ok = |x: f32| {
        let b = x.to_bits();
        (b == 0) | (b.wrapping_sub(low) <= span)
    };
    match alpha0 {
        None => texels.iter().fold(true, |all, x| all & ok(x[3])),
        Some(a0) => {
            // Every channel of every texel, over the flat values (eight to a register).
            texels.as_flattened().iter().fold(true, |all, &x| all & ok(x))
                && a0.iter().fold(true, |all, &x| all & ok(x))
        }
    }
}
