//! SSE kernels of the SH stage ([`super::sh`]) on x86-64, four floats at a time.
//!
//! Each kernel performs exactly the multiplications and additions of its scalar reference in
//! `sh.rs`, in the same order and with the same operand order (SSE2 is part of the x86-64
//! baseline, and `mulps`/`addps` round each lane as `mulss`/`addss` do, with no fused
//! multiply-add), so the results are identical bit for bit. (Except the payload of a NaN
//! result, which Rust leaves unspecified in the scalar code too.) The tests in `sh.rs` compare
//! both on random and special inputs.
//!
//! Layout: coefficients `[coeff k][rgb]` interleaved, so 4 basis functions span 12 floats, three
//! SSE vectors; the channel of float `3k + c` repeats with period 3.

use std::arch::x86_64::{
    __m128, _mm_add_ps, _mm_loadu_ps, _mm_mul_ps, _mm_set_ps, _mm_set1_ps, _mm_shuffle_ps, _mm_storeu_ps,
};

/// `[a[i], a[j], b[k], b[l]]`.
macro_rules! shuffle {
    ($a:expr, $b:expr, $i:literal, $j:literal, $k:literal, $l:literal) => {
        _mm_shuffle_ps::<{ ($l << 6) | ($k << 4) | ($j << 2) | $i }>($a, $b)
    };
}

/// The coefficient pass of the SH backward for the first `n` basis functions: for `k < n` and
/// each channel `c`, `d_coeffs[3k + c] += basis[k] · g[c]`, and `d_basis[k] = (g[0]·coeffs[3k] +
/// g[1]·coeffs[3k + 1]) + g[2]·coeffs[3k + 2]`. Groups of four basis functions are done in SSE,
/// the rest (`n mod 4`) by the scalar reference.
///
/// # Panics
/// When `coeffs` or `d_coeffs` holds fewer than `3n` floats or `n > 16`.
#[inline]
pub(crate) fn coefficient_pass(
    n: usize,
    coeffs: &[f32],
    basis: &[f32; 16],
    g: [f32; 3],
    d_coeffs: &mut [f32],
    d_basis: &mut [f32; 16],
) {
    assert!(n <= 16, "at most 16 basis functions");
    let (coeffs, d_coeffs) = (&coeffs[..3 * n], &mut d_coeffs[..3 * n]);
    let groups = n / 4;
    // SAFETY: SSE is always available on x86-64. Group `j` reads and writes floats
    // `12j..12j + 12` of `coeffs` and `d_coeffs` (within their `3n` floats as `4(j + 1) ≤ n`) and
    // floats `4j..4j + 4` of `basis` and `d_basis` (within 16 as `n ≤ 16`, asserted); unaligned
    // loads and stores.
    unsafe {
        // The channel pattern of floats 0..4, 4..8 and 8..12 of a group.
        let g0 = _mm_set_ps(g[0], g[2], g[1], g[0]);
        let g1 = _mm_set_ps(g[1], g[0], g[2], g[1]);
        let g2 = _mm_set_ps(g[2], g[1], g[0], g[2]);
        for j in 0..groups {
            let b = _mm_loadu_ps(basis.as_ptr().add(4 * j));
            // Y₀..Y₃ spread over the group's floats: [Y₀ Y₀ Y₀ Y₁] [Y₁ Y₁ Y₂ Y₂] [Y₂ Y₃ Y₃ Y₃].
            let spread = [
                shuffle!(b, b, 0, 0, 0, 1),
                shuffle!(b, b, 1, 1, 2, 2),
                shuffle!(b, b, 2, 3, 3, 3),
            ];
            let gs = [g0, g1, g2];
            let mut products = [_mm_set1_ps(0.0); 3];
            for v in 0..3 {
                let at = 12 * j + 4 * v;
                let d = d_coeffs.as_mut_ptr().add(at);
                _mm_storeu_ps(d, _mm_add_ps(_mm_loadu_ps(d), _mm_mul_ps(spread[v], gs[v])));
                products[v] = _mm_mul_ps(gs[v], _mm_loadu_ps(coeffs.as_ptr().add(at)));
            }
            // Products p0..p11 of the group; basis function k sums p[3k], p[3k + 1], p[3k + 2].
            let [p0, p1, p2] = products;
            let first = shuffle!(p0, shuffle!(p1, p2, 2, 2, 1, 1), 0, 3, 0, 2); // p0 p3 p6 p9
            let second = shuffle!(shuffle!(p0, p1, 1, 1, 0, 0), shuffle!(p1, p2, 3, 3, 2, 2), 0, 2, 0, 2); // p1 p4 p7 p10
            let third = shuffle!(shuffle!(p0, p1, 2, 2, 1, 1), p2, 0, 2, 0, 3); // p2 p5 p8 p11
            _mm_storeu_ps(
                d_basis.as_mut_ptr().add(4 * j),
                _mm_add_ps(_mm_add_ps(first, second), third),
            );
        }
    }
    // The last `n mod 4` basis functions: the scalar reference itself.
    let done = 4 * groups;
    super::sh::coefficient_pass_scalar(
        n - done,
        &coeffs[3 * done..],
        &basis[done..],
        g,
        &mut d_coeffs[3 * done..],
        &mut d_basis[done..],
    );
}

/// The raw colours of `L` primitives with `n` basis functions each: per primitive and channel
/// `0.5 + Σₖ basis[k]·coeffs[3k + c]`, summed in increasing `k`. The `L` sums advance together
/// (their dependency chains interleave); each primitive's channels share one SSE vector (its
/// fourth lane is discarded).
///
/// # Panics
/// When a coefficient slice holds fewer than `3n` floats or `n > 16`.
#[inline]
pub(crate) fn raw_colours<const L: usize>(n: usize, coeffs: [&[f32]; L], basis: &[[f32; 16]; L]) -> [[f32; 3]; L] {
    for c in &coeffs {
        assert!(c.len() >= 3 * n, "need 3·(degree + 1)² coefficients");
    }
    assert!(n <= 16, "at most 16 basis functions");
    // SAFETY: SSE is always available on x86-64. Coefficient `k` reads floats `3k..3k + 4` of a
    // slice only when they lie inside it (checked per read), else builds the vector from the
    // three floats `3k..3k + 3`, which lie inside as `k < n` and the slice holds `3n`.
    unsafe {
        let mut acc: [__m128; L] = [_mm_set1_ps(0.5); L];
        for k in 0..n {
            for l in 0..L {
                let c = coeffs[l];
                let row = if 3 * k + 4 <= c.len() {
                    _mm_loadu_ps(c.as_ptr().add(3 * k))
                } else {
                    _mm_set_ps(0.0, c[3 * k + 2], c[3 * k + 1], c[3 * k])
                };
                acc[l] = _mm_add_ps(acc[l], _mm_mul_ps(_mm_set1_ps(basis[l][k]), row));
            }
        }
        acc.map(|v| {
            let mut out = [0.0f32; 4];
            _mm_storeu_ps(out.as_mut_ptr(), v);
            [out[0], out[1], out[2]]
        })
    }
}
