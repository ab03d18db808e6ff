//! The regularisers' row sums: the four-way fast path against the texel-order definition, bit
//! for bit, and the condition that chooses it.

use bbsplat::cpu::Simd;
use bbsplat::rng::Rng;
use bbsplat::train::row_sums::{RowSums, exact_in_any_order, row_sums, row_sums_in_order};

fn bits(s: RowSums) -> [u64; 3] {
    [s.colour.to_bits(), s.alpha.to_bits(), s.alpha_offset.to_bits()]
}

/// `2^(⌈log₂(3·texels)⌉ − 30)`, the condition's threshold (module docs).
fn threshold(texels: usize) -> f32 {
    2f32.powi((3 * texels).next_power_of_two().trailing_zeros() as i32 - 30)
}

/// A value drawn so that sums of many of them round in f64 unless all lie at or above
/// `2^low_exponent`: `+0`, `1`, the threshold and its neighbours, uniform in `[0, 1]`, and
/// log-uniform down to `2^low_exponent`.
fn value(rng: &mut Rng, tau: f32, low_exponent: i32) -> f32 {
    match rng.below(8) {
        0 => 0.0,
        1 => 1.0,
        2 => tau,
        3 => f32::from_bits(tau.to_bits() + 1),
        4 => rng.uniform().max(2f32.powi(low_exponent)),
        // `powf` may round to one ulp below `2^low_exponent`: kept at or above it.
        _ => 2f32
            .powf(low_exponent as f32 * rng.uniform())
            .max(2f32.powi(low_exponent)),
    }
}

fn row(rng: &mut Rng, texels: usize, tau: f32, low_exponent: i32) -> (Vec<[f32; 4]>, Vec<f32>) {
    let tex = (0..texels)
        .map(|_| std::array::from_fn(|_| value(rng, tau, low_exponent)))
        .collect();
    let alpha0 = (0..texels).map(|_| value(rng, tau, low_exponent)).collect();
    (tex, alpha0)
}

/// Rows whose every value is `+0` or in `[τ, 1]` take the fast path, and it gives the bits of
/// the texel-order sums; with and without the reference alpha; at texture sizes 2, 6, 16, 18
/// (`3·T` just under 1024) and 19 (just over: a threshold twice as high). The values go down to
/// the threshold and include long log-uniform tails, so the texel-order sums are far from
/// trivial (rows of values spread over 20 binades). In the AVX2 and the baseline build.
#[test]
fn the_fast_path_gives_the_texel_order_bits() {
    for simd in [Simd::detect(), Simd::BASELINE] {
        fast_path_rows(simd);
    }
}

/// The rows of [`the_fast_path_gives_the_texel_order_bits`], in the build `simd` selects (AVX2
/// or baseline).
fn fast_path_rows(simd: Simd) {
    let mut rng = Rng::new(7);
    let mut fast = 0;
    for ts in [2usize, 6, 16, 18, 19] {
        let texels = ts * ts;
        let tau = threshold(texels);
        let low = tau.log2() as i32;
        for _ in 0..400 {
            let (tex, alpha0) = row(&mut rng, texels, tau, low);
            for a0 in [None, Some(alpha0.as_slice())] {
                assert!(exact_in_any_order(&tex, a0), "TS {ts}: every value is 0 or in [τ, 1]");
                assert_eq!(
                    bits(row_sums(&tex, a0, simd)),
                    bits(row_sums_in_order(&tex, a0)),
                    "TS {ts}"
                );
                fast += 1;
            }
        }
    }
    assert_eq!(fast, 4000);
}

/// Rows with values below the threshold (down to `2⁻³⁰`) still give the texel-order bits, and
/// fail the condition. This is the test that catches a threshold set too low: the values between
/// `2⁻³⁰` and `τ` make the four-way order round differently from the texel order in most rows
/// (the last assertion, with the four-way order written out here), so a fast path allowed on
/// them fails the bit comparison (measured: moving the threshold's exponent from `L − 30` to
/// `L − 40` fails it).
#[test]
fn rows_below_the_threshold_take_the_texel_order() {
    let mut rng = Rng::new(11);
    let texels = 256;
    let tau = threshold(texels);
    assert_eq!(tau, 2f32.powi(-20));
    let mut differing = 0;
    for _ in 0..200 {
        let (tex, alpha0) = row(&mut rng, texels, tau, -30);
        let want = row_sums_in_order(&tex, Some(&alpha0));
        assert_eq!(bits(row_sums(&tex, Some(&alpha0), Simd::detect())), bits(want));
        assert!(!exact_in_any_order(&tex, Some(&alpha0)), "some value lies below τ");
        // The four-way order, as the fast path sums.
        let four_way: f64 = (0..4)
            .map(|j| {
                tex.iter()
                    .skip(j)
                    .step_by(4)
                    .fold(0.0, |s, x| s + (x[0] as f64 + x[1] as f64 + x[2] as f64))
            })
            .sum();
        differing += usize::from(four_way.to_bits() != want.colour.to_bits());
    }
    assert!(
        differing > 100,
        "the orders differ on most such rows: {differing} of 200"
    );
}

/// Each kind of value that breaks the condition, alone in an otherwise exact row: one in
/// `(0, τ)`, the largest `f32` below `τ`, a subnormal, `−0.0`, a negative value, a value above
/// 1, infinity and NaN; in the alpha channel (always read), in a colour channel and in the
/// reference alpha (read only with the reference alpha).
#[test]
fn each_breaking_value_is_refused() {
    let texels = 256;
    let tau = threshold(texels);
    let base: Vec<[f32; 4]> = (0..texels).map(|k| [0.25, 0.5, 1.0, (k % 7) as f32 / 7.0]).collect();
    let alpha0 = vec![0.5f32; texels];
    assert!(exact_in_any_order(&base, Some(&alpha0)));
    assert!(exact_in_any_order(&base, None));
    let breaking = [
        tau / 2.0,
        f32::from_bits(tau.to_bits() - 1),
        f32::from_bits(1),
        -0.0,
        -0.5,
        f32::from_bits(1f32.to_bits() + 1),
        f32::INFINITY,
        f32::NAN,
    ];
    for x in breaking {
        let mut tex = base.clone();
        tex[100][3] = x;
        assert!(!exact_in_any_order(&tex, None), "alpha {x:e}");
        assert!(!exact_in_any_order(&tex, Some(&alpha0)), "alpha {x:e}");
        let mut tex = base.clone();
        tex[37][1] = x;
        assert!(
            exact_in_any_order(&tex, None),
            "colour {x:e} is not read without alpha0"
        );
        assert!(!exact_in_any_order(&tex, Some(&alpha0)), "colour {x:e}");
        let mut a0 = alpha0.clone();
        a0[200] = x;
        assert!(!exact_in_any_order(&base, Some(&a0)), "alpha0 {x:e}");
        // Whichever path, the texel-order bits (NaN compared by its bits too).
        for (t, a) in [(&tex, &alpha0), (&base, &a0)] {
            assert_eq!(
                bits(row_sums(t, Some(a), Simd::detect())),
                bits(row_sums_in_order(t, Some(a)))
            );
        }
    }
}
