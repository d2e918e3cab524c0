//! Symmetric positive definite sparse systems solved exactly: a fill-reducing ordering
//! (approximate minimum degree, the `amd` crate) and an LDLᵀ factorization (the `ldl` crate).
//!
//! The walk over a reconstruction's points (`point_walk.rs`) solves one grounded graph
//! Laplacian per class. Conjugate gradients stopped far from the solution there (the graph has
//! edges of weight 1e-9 next to edges of weight 1, so the system is badly conditioned), and the
//! labels depended on where they stopped; the factorization gives the solution itself, and one
//! factorization serves every class (docs/results/quality-log.md, "The walk over the points solved exactly").
use thiserror::Error;

/// Added to every diagonal entry, relative to the mean diagonal: it makes a system whose graph
/// has a part without any seed (singular, with a zero right-hand side there) definite, with the
/// solution 0 there, as conjugate gradients started from 0 left it.
const REGULARIZATION: f64 = 1e-12;

#[derive(Debug, Error, PartialEq)]
pub enum SolveError {
    #[error("the fill-reducing ordering refused the system ({0})")]
    Ordering(String),
    #[error("the system is not positive definite: the factorization failed at pivot {0}")]
    NotDefinite(usize),
}

/// The LDLᵀ factors of a symmetric positive definite matrix, rows and columns taken in a
/// fill-reducing order.
pub struct Factored {
    /// `order[k]` is the original index of the k-th row in the factored order.
    order: Vec<usize>,
    l_p: Vec<usize>,
    l_i: Vec<usize>,
    l_x: Vec<f64>,
    d_inv: Vec<f64>,
}

impl Factored {
    /// Factors the n x n matrix with `diagonal[k]` on its diagonal and, for row k, the entries
    /// `links[starts[k]..starts[k + 1]]` (column, value) off it. The matrix must be symmetric:
    /// every (k, j, v) has its (j, k, v).
    pub fn new(diagonal: &[f64], starts: &[usize], links: &[(u32, f64)]) -> Result<Factored, SolveError> {
        let n = diagonal.len();
        debug_assert_eq!(starts.len(), n + 1);
        if n == 0 {
            return Ok(Factored {
                order: Vec::new(),
                l_p: vec![0],
                l_i: Vec::new(),
                l_x: Vec::new(),
                d_inv: Vec::new(),
            });
        }
        // The full pattern with its diagonal, by column (symmetric, so rows and columns agree).
        let mut a_p = Vec::with_capacity(n + 1);
        let mut a_i = Vec::with_capacity(links.len() + n);
        for k in 0..n {
            a_p.push(a_i.len());
            let mut column: Vec<usize> = links[starts[k]..starts[k + 1]]
                .iter()
                .map(|&(j, _)| j as usize)
                .collect();
            column.push(k);
            column.sort_unstable();
            column.dedup();
            a_i.extend(column);
        }
        a_p.push(a_i.len());
        let (order, inverse, _) = amd::order(n, &a_p, &a_i, &amd::Control::default())
            .map_err(|status| SolveError::Ordering(format!("{status:?}")))?;

        // The upper triangle of the reordered matrix, by column, rows sorted.
        let mean_diagonal = diagonal.iter().sum::<f64>() / n as f64;
        let shift = REGULARIZATION * mean_diagonal.max(f64::MIN_POSITIVE);
        let mut columns: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        for k in 0..n {
            let pk = inverse[k];
            columns[pk].push((pk, diagonal[k] + shift));
            for &(j, v) in &links[starts[k]..starts[k + 1]] {
                let pj = inverse[j as usize];
                if pj < pk {
                    columns[pk].push((pj, v));
                }
            }
        }
        let mut u_p = Vec::with_capacity(n + 1);
        let mut u_i = Vec::new();
        let mut u_x = Vec::new();
        for column in &mut columns {
            let start = u_i.len();
            u_p.push(start);
            column.sort_unstable_by_key(|&(row, _)| row);
            for &(row, value) in column.iter() {
                // A link listed twice adds up, as in the matrix it stands for.
                match u_x.last_mut() {
                    Some(last) if u_i.len() > start && u_i.last() == Some(&row) => *last += value,
                    _ => {
                        u_i.push(row);
                        u_x.push(value);
                    }
                }
            }
        }
        u_p.push(u_i.len());

        let mut l_nz = vec![0usize; n];
        let mut etree = vec![None; n];
        let mut iwork = vec![0usize; 3 * n];
        let below =
            ldl::etree(n, &u_p, &u_i, &mut iwork, &mut l_nz, &mut etree).map_err(|_| SolveError::NotDefinite(0))?;
        let mut l_p = vec![0usize; n + 1];
        let mut l_i = vec![0usize; below];
        let mut l_x = vec![0f64; below];
        let mut d = vec![0f64; n];
        let mut d_inv = vec![0f64; n];
        let mut bwork = vec![ldl::Marker::Unused; n];
        let mut fwork = vec![0f64; n];
        ldl::factor(
            n, &u_p, &u_i, &u_x, &mut l_p, &mut l_i, &mut l_x, &mut d, &mut d_inv, &l_nz, &etree, &mut bwork,
            &mut iwork, &mut fwork,
        )
        .map_err(|_| SolveError::NotDefinite(d.iter().position(|&v| v <= 0.0).unwrap_or(0)))?;
        if let Some(pivot) = d.iter().position(|&v| v.is_nan() || v <= 0.0) {
            return Err(SolveError::NotDefinite(pivot));
        }
        Ok(Factored {
            order,
            l_p,
            l_i,
            l_x,
            d_inv,
        })
    }

    /// x with A x = b.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let n = self.order.len();
        let mut x: Vec<f64> = self.order.iter().map(|&k| b[k]).collect();
        ldl::solve(n, &self.l_p, &self.l_i, &self.l_x, &self.d_inv, &mut x);
        let mut out = vec![0f64; n];
        for (k, &original) in self.order.iter().enumerate() {
            out[original] = x[k];
        }
        out
    }

    /// Entries of the factor below its diagonal (the fill the ordering left).
    pub fn factor_entries(&self) -> usize {
        self.l_x.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric system as the walks store it, from a dense matrix.
    fn links_of(dense: &[Vec<f64>]) -> (Vec<f64>, Vec<usize>, Vec<(u32, f64)>) {
        let mut starts = vec![0];
        let mut links = Vec::new();
        for (k, row) in dense.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                if j != k && v != 0.0 {
                    links.push((j as u32, v));
                }
            }
            starts.push(links.len());
        }
        (dense.iter().enumerate().map(|(k, row)| row[k]).collect(), starts, links)
    }

    fn multiply(dense: &[Vec<f64>], x: &[f64]) -> Vec<f64> {
        dense
            .iter()
            .map(|row| row.iter().zip(x).map(|(a, b)| a * b).sum())
            .collect()
    }

    #[test]
    fn solves_a_grounded_laplacian_of_a_ring() {
        // A ring of 40 nodes with uneven weights, node 0 grounded to 1 and node 20 to 0: the
        // free nodes' system, which the walks solve.
        let n = 40;
        let weight = |i: usize| 0.1 + (i * 7 % 11) as f64 / 3.0;
        let free: Vec<usize> = (0..n).filter(|&i| i != 0 && i != 20).collect();
        let slot = |i: usize| free.iter().position(|&f| f == i);
        let mut dense = vec![vec![0f64; free.len()]; free.len()];
        let mut rhs = vec![0f64; free.len()];
        for i in 0..n {
            let j = (i + 1) % n;
            let w = weight(i);
            for (a, b) in [(i, j), (j, i)] {
                if let Some(sa) = slot(a) {
                    dense[sa][sa] += w;
                    match slot(b) {
                        Some(sb) => dense[sa][sb] -= w,
                        None if b == 0 => rhs[sa] += w,
                        None => {}
                    }
                }
            }
        }
        let (diagonal, starts, links) = links_of(&dense);
        let factored = Factored::new(&diagonal, &starts, &links).unwrap();
        let x = factored.solve(&rhs);
        let back = multiply(&dense, &x);
        for (got, want) in back.iter().zip(&rhs) {
            assert!((got - want).abs() < 1e-9, "{got} against {want}");
        }
        assert!(x.iter().all(|&p| (0.0..=1.0).contains(&p)), "probabilities: {x:?}");
    }

    #[test]
    fn a_part_without_seeds_solves_to_zero() {
        // Two free nodes linked to each other only: singular without the shift, and the
        // right-hand side is zero there.
        let (diagonal, starts, links) = links_of(&[vec![1.0, -1.0], vec![-1.0, 1.0]]);
        let factored = Factored::new(&diagonal, &starts, &links).unwrap();
        assert_eq!(factored.solve(&[0.0, 0.0]), vec![0.0, 0.0]);
    }

    #[test]
    fn an_indefinite_matrix_is_refused() {
        let (diagonal, starts, links) = links_of(&[vec![1.0, 2.0], vec![2.0, 1.0]]);
        assert!(matches!(
            Factored::new(&diagonal, &starts, &links),
            Err(SolveError::NotDefinite(_))
        ));
    }
}
