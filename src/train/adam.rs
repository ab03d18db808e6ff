//! Row-sparse Adam: only the rows (billboards) that received a gradient are updated.

/// First and second moments of one parameter group, `row_len` values per billboard.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamGroup {
    /// Values per billboard.
    pub row_len: usize,
    /// First moments.
    pub m: Vec<f32>,
    /// Second moments.
    pub v: Vec<f32>,
    /// Per billboard: number of updates applied (for bias correction).
    pub steps: Vec<u32>,
}

/// Adam hyper-parameters (reference: β₁ 0.9, β₂ 0.999, ε 1e-15).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// β₁.
    pub beta1: f32,
    /// β₂.
    pub beta2: f32,
    /// ε.
    pub eps: f32,
}

impl Default for AdamParams {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

impl AdamGroup {
    /// Zero moments for `rows` billboards of `row_len` values.
    pub fn new(rows: usize, row_len: usize) -> Self {
        Self {
            row_len,
            m: vec![0.0; rows * row_len],
            v: vec![0.0; rows * row_len],
            steps: vec![0; rows],
        }
    }

    /// One Adam step for billboard `row`: `params -= lr · m̂ / (√v̂ + ε)`, with bias correction by
    /// the number of updates this row has received. Dense PyTorch Adam would also decay the
    /// moments of rows with zero gradient and keep moving them; here a billboard that is not
    /// seen in a view is left exactly as it is. This saves the work on unseen rows; how much it saves
    /// and what it changes in quality against dense Adam has not been measured yet.
    pub fn step_row(&mut self, row: usize, params: &mut [f32], grads: &[f32], lr: f32, hp: &AdamParams) {
        let n = self.row_len;
        debug_assert_eq!(params.len(), n);
        debug_assert_eq!(grads.len(), n);
        self.steps[row] += 1;
        let t = self.steps[row] as i32;
        let bc1 = 1.0 - hp.beta1.powi(t);
        let bc2 = 1.0 - hp.beta2.powi(t);
        let m = &mut self.m[row * n..(row + 1) * n];
        let v = &mut self.v[row * n..(row + 1) * n];
        for k in 0..n {
            let g = grads[k];
            m[k] = hp.beta1 * m[k] + (1.0 - hp.beta1) * g;
            v[k] = hp.beta2 * v[k] + (1.0 - hp.beta2) * g * g;
            params[k] -= lr * (m[k] / bc1) / ((v[k] / bc2).sqrt() + hp.eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_against_the_gradient_sign() {
        let mut g = AdamGroup::new(2, 3);
        let mut p = [1.0f32, 2.0, 3.0];
        g.step_row(1, &mut p, &[0.5, -2.0, 0.0], 0.1, &AdamParams::default());
        assert!((p[0] - 0.9).abs() < 1e-6 && (p[1] - 2.1).abs() < 1e-6 && p[2] == 3.0);
        assert_eq!(g.steps, vec![0, 1]);
    }

    #[test]
    fn minimises_a_quadratic() {
        let mut g = AdamGroup::new(1, 1);
        let mut p = [5.0f32];
        for _ in 0..2000 {
            let grad = [2.0 * (p[0] - 1.5)];
            g.step_row(
                0,
                &mut p,
                &grad,
                0.01,
                &AdamParams {
                    eps: 1e-8,
                    ..Default::default()
                },
            );
        }
        assert!((p[0] - 1.5).abs() < 1e-2, "{}", p[0]);
    }
}
