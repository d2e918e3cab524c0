//! Fitting and applying the 3-component PCA that turns D-dimensional feature vectors into a
//! displayable colour (the archive's `Pca` block, and the renderer's view of rendered features).
//!
//! Fitting uses the D×D covariance and power iteration with deflation: D is 64 here, so the
//! covariance is tiny and three iterated matrix-vector products are all the linear algebra
//! needed (no LAPACK). The colour range `lo..hi` of each component is taken between the 1st and
//! 99th percentile of the projections, so a few outliers do not wash the picture out.
use super::manifest::Pca;

/// Power iterations per component; the covariance of real features has well separated leading
/// eigenvalues, and the result only colours a picture.
const POWER_ITERATIONS: usize = 64;

impl Pca {
    /// Fits the PCA of `values`, rows of `dim` numbers. Rows with a non-finite value are skipped.
    /// Returns `None` when fewer than two usable rows exist or `dim` is 0.
    pub fn fit(values: &[f32], dim: usize) -> Option<Pca> {
        if dim == 0 {
            return None;
        }
        let rows: Vec<&[f32]> = values
            .chunks_exact(dim)
            .filter(|r| r.iter().all(|v| v.is_finite()))
            .collect();
        if rows.len() < 2 {
            return None;
        }
        let n = rows.len() as f64;
        let mut mean = vec![0.0f64; dim];
        for r in &rows {
            for (m, &v) in mean.iter_mut().zip(r.iter()) {
                *m += f64::from(v);
            }
        }
        mean.iter_mut().for_each(|m| *m /= n);
        let mut cov = vec![0.0f64; dim * dim];
        let mut centred = vec![0.0f64; dim];
        for r in &rows {
            for (c, (&v, &m)) in centred.iter_mut().zip(r.iter().zip(&mean)) {
                *c = f64::from(v) - m;
            }
            for i in 0..dim {
                let ci = centred[i];
                for j in i..dim {
                    cov[i * dim + j] += ci * centred[j];
                }
            }
        }
        for i in 0..dim {
            for j in i..dim {
                let v = cov[i * dim + j] / n;
                cov[i * dim + j] = v;
                cov[j * dim + i] = v;
            }
        }
        let mut components: [Vec<f32>; 3] = Default::default();
        for (k, component) in components.iter_mut().enumerate() {
            let v = leading_eigenvector(&cov, dim, k);
            // Deflate so the next iteration finds the next component.
            let lambda = rayleigh(&cov, dim, &v);
            for i in 0..dim {
                for j in 0..dim {
                    cov[i * dim + j] -= lambda * v[i] * v[j];
                }
            }
            *component = v.iter().map(|&x| x as f32).collect();
        }
        let mut pca = Pca {
            mean: mean.iter().map(|&m| m as f32).collect(),
            components,
            lo: [0.0; 3],
            hi: [1.0; 3],
        };
        let projections: Vec<[f32; 3]> = rows.iter().map(|r| pca.project(r)).collect();
        for k in 0..3 {
            let mut p: Vec<f32> = projections.iter().map(|v| v[k]).collect();
            p.sort_by(f32::total_cmp);
            let at = |q: f64| p[((p.len() - 1) as f64 * q).round() as usize];
            let (lo, hi) = (at(0.01), at(0.99));
            pca.lo[k] = lo;
            // A flat component (all projections equal) still maps to a valid colour.
            pca.hi[k] = if hi > lo { hi } else { lo + 1.0 };
        }
        Some(pca)
    }

    /// The three principal coordinates of `code` (`code.len()` must be the PCA's dimension).
    pub fn project(&self, code: &[f32]) -> [f32; 3] {
        std::array::from_fn(|k| {
            code.iter()
                .zip(&self.mean)
                .zip(&self.components[k])
                .map(|((&x, &m), &c)| (x - m) * c)
                .sum()
        })
    }

    /// `code` as a colour in [0,1]³: each principal coordinate scaled from `lo..hi`, clamped.
    pub fn colour(&self, code: &[f32]) -> [f32; 3] {
        let p = self.project(code);
        std::array::from_fn(|k| ((p[k] - self.lo[k]) / (self.hi[k] - self.lo[k])).clamp(0.0, 1.0))
    }
}

fn leading_eigenvector(cov: &[f64], dim: usize, k: usize) -> Vec<f64> {
    // A fixed start that is not orthogonal to any axis in general; varied by k so a deflated
    // matrix does not start on the previous component.
    let mut v: Vec<f64> = (0..dim).map(|i| 1.0 + ((i * 7 + k * 13) % 11) as f64 * 0.1).collect();
    normalize(&mut v);
    let mut next = vec![0.0; dim];
    for _ in 0..POWER_ITERATIONS {
        for (i, out) in next.iter_mut().enumerate() {
            *out = cov[i * dim..(i + 1) * dim].iter().zip(&v).map(|(a, b)| a * b).sum();
        }
        if normalize(&mut next) == 0.0 {
            // Nothing left in this direction (rank below 3): any unit vector does.
            break;
        }
        std::mem::swap(&mut v, &mut next);
    }
    // A deterministic sign: the largest entry positive, so refits give the same colours.
    let largest = v
        .iter()
        .copied()
        .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
    if largest < 0.0 {
        v.iter_mut().for_each(|x| *x = -*x);
    }
    v
}

fn rayleigh(cov: &[f64], dim: usize, v: &[f64]) -> f64 {
    (0..dim)
        .map(|i| {
            v[i] * cov[i * dim..(i + 1) * dim]
                .iter()
                .zip(v)
                .map(|(a, b)| a * b)
                .sum::<f64>()
        })
        .sum()
}

fn normalize(v: &mut [f64]) -> f64 {
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points spread mostly along known orthogonal directions are recovered in order.
    #[test]
    fn recovers_the_axes_of_an_anisotropic_cloud() {
        let dim = 5;
        let mut values = Vec::new();
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        for _ in 0..2000 {
            let (a, b, c) = (uniform() * 10.0, uniform() * 4.0, uniform() * 1.0);
            // Axes: e2, e0, e4; plus a little isotropic noise.
            let mut row = vec![0.0f32; dim];
            row[2] = a + 3.0;
            row[0] = b - 1.0;
            row[4] = c;
            for v in row.iter_mut() {
                *v += uniform() * 0.01;
            }
            values.extend(row);
        }
        let pca = Pca::fit(&values, dim).unwrap();
        for (k, axis) in [2usize, 0, 4].into_iter().enumerate() {
            assert!(
                pca.components[k][axis].abs() > 0.99,
                "component {k} = {:?} should lie along axis {axis}",
                pca.components[k]
            );
        }
        assert!((pca.mean[2] - 3.0).abs() < 0.3, "mean {:?}", pca.mean);
        for k in 0..3 {
            assert!(pca.hi[k] > pca.lo[k]);
        }
        let c = pca.colour(&[-1.0, 0.0, 3.0, 0.0, 0.0]);
        assert!(c.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!((c[0] - 0.5).abs() < 0.1, "the mean maps to mid-range: {c:?}");
    }

    #[test]
    fn degenerate_inputs() {
        assert!(Pca::fit(&[], 4).is_none());
        assert!(Pca::fit(&[1.0, 2.0], 2).is_none(), "one row has no spread");
        // Rank 1: the later components are still unit vectors or zero, and colours are finite.
        let values: Vec<f32> = (0..100).flat_map(|i| [i as f32, 0.0, 0.0]).collect();
        let pca = Pca::fit(&values, 3).unwrap();
        assert!(pca.components[0][0] > 0.99);
        assert!(pca.colour(&[50.0, 0.0, 0.0]).iter().all(|v| v.is_finite()));
        // Non-finite rows are skipped.
        let mut values = values.clone();
        values[0] = f32::NAN;
        assert!(Pca::fit(&values, 3).is_some());
    }
}
