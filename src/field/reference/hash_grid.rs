//! Multiresolution hash encoding (instant-ngp), forward and backward.
//!
//! Level `l` has `res_l = floor(base · scale^l)` cells per axis, so `res_l + 1` vertices.
//! A position p ∈ [0,1]³ (clamped) lands at `x = p · res_l` in grid units; its cell is
//! `min(floor(x), res_l − 1)` (so p = 1 uses the last cell, never a vertex past the grid) and
//! its 8 corners are blended trilinearly. A corner's entry within the level's table is
//! - dense `x + y·(res+1) + z·(res+1)²` when `(res+1)³ ≤ table_size`, so coarse levels have no
//!   collisions, else
//! - the spatial hash `(x·1 ⊕ y·2654435761 ⊕ z·805459861) mod table_size` in wrapping u32
//!   arithmetic (table_size is a power of two, so the mod is a mask).
//!
//! Each level holds `min((res+1)³, table_size)` entries (instant-ngp's sizing): a dense level
//! has exactly one entry per vertex, a hashed one the whole table. The levels follow each other
//! in the flat table, so value `f` of entry `e` of level `l` is at
//! `(level_offset(l) + e) · F + f` (`field::params`). Positions are data, not parameters, so
//! the backward pass only produces table gradients.
use super::real::Real;
use crate::field::config::FieldConfig;

pub const HASH_PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// The derived geometry of a hash grid: everything a kernel needs as uniforms.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HashGrid {
    pub levels: usize,
    pub features: usize,
    /// Entries of a hashed level (a power of two); a dense level holds fewer.
    pub table_size: usize,
    /// Cells per axis of every level.
    pub resolutions: Vec<u32>,
    /// Entry where each level starts in the flat table, and the total after the last level
    /// (`levels + 1` values).
    pub level_offsets: Vec<usize>,
}

/// One corner of the cell containing a position: its table slot and trilinear weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Corner<R> {
    /// Index of the corner's first feature in the flat table.
    pub offset: usize,
    pub weight: R,
}

impl HashGrid {
    pub fn new(levels: usize, features: usize, log2_table_size: u32, base_resolution: u32, scale: f32) -> HashGrid {
        let resolutions: Vec<u32> = (0..levels)
            .map(|l| ((base_resolution as f64 * (scale as f64).powi(l as i32)).floor() as u32).max(1))
            .collect();
        let table_size = 1usize << log2_table_size;
        let mut level_offsets = vec![0usize];
        for &res in &resolutions {
            let entries = level_entries(res, table_size);
            level_offsets.push(level_offsets.last().copied().unwrap_or(0) + entries);
        }
        HashGrid {
            levels,
            features,
            table_size,
            resolutions,
            level_offsets,
        }
    }

    pub fn from_config(cfg: &FieldConfig) -> HashGrid {
        let levels = if cfg.encoding.uses_hash_grid() {
            cfg.hash_levels as usize
        } else {
            0
        };
        HashGrid::new(
            levels,
            cfg.hash_features_per_level as usize,
            cfg.log2_hash_table_size,
            cfg.hash_base_resolution,
            cfg.hash_level_scale,
        )
    }

    /// Values produced per position: levels × features, level-major.
    pub fn output_dim(&self) -> usize {
        self.levels * self.features
    }

    /// Length of the table: the entries of every level × features.
    pub fn param_count(&self) -> usize {
        self.level_offsets[self.levels] * self.features
    }

    /// Whether the level's vertex grid fits its table, so it is indexed densely.
    pub fn is_dense(&self, level: usize) -> bool {
        is_dense(self.resolutions[level], self.table_size)
    }

    /// Entries the level holds: `(res+1)³` when dense, else `table_size`.
    pub fn level_entries(&self, level: usize) -> usize {
        self.level_offsets[level + 1] - self.level_offsets[level]
    }

    /// The level a value of the flat table belongs to.
    pub fn level_of_value(&self, index: usize) -> usize {
        let entry = index / self.features.max(1);
        self.level_offsets[1..].partition_point(|&end| end <= entry)
    }

    /// Entry of an integer vertex within the level's table.
    pub fn entry(&self, level: usize, vertex: [u32; 3]) -> usize {
        if self.is_dense(level) {
            let v = self.resolutions[level] as usize + 1;
            vertex[0] as usize + vertex[1] as usize * v + vertex[2] as usize * v * v
        } else {
            let h = vertex[0].wrapping_mul(HASH_PRIMES[0])
                ^ vertex[1].wrapping_mul(HASH_PRIMES[1])
                ^ vertex[2].wrapping_mul(HASH_PRIMES[2]);
            (h as usize) & (self.table_size - 1)
        }
    }

    /// The 8 corners of the cell holding `pos` on `level`, corner `c` taking the upper vertex on
    /// axis `d` when bit `d` of `c` is set.
    pub fn corners<R: Real>(&self, level: usize, pos: [R; 3]) -> [Corner<R>; 8] {
        let res = self.resolutions[level];
        let mut cell = [0u32; 3];
        let mut frac = [R::ZERO; 3];
        for d in 0..3 {
            let x = pos[d].clamp(R::ZERO, R::ONE) * R::of(res as f64);
            let c = (x.floor().to_f64() as u32).min(res - 1);
            cell[d] = c;
            frac[d] = x - R::of(c as f64);
        }
        let level_base = self.level_offsets[level];
        std::array::from_fn(|c| {
            let mut vertex = cell;
            let mut weight = R::ONE;
            for d in 0..3 {
                if c & (1 << d) != 0 {
                    vertex[d] += 1;
                    weight *= frac[d];
                } else {
                    weight *= R::ONE - frac[d];
                }
            }
            Corner {
                offset: (level_base + self.entry(level, vertex)) * self.features,
                weight,
            }
        })
    }
}

fn is_dense(resolution: u32, table_size: usize) -> bool {
    let v = resolution as u64 + 1;
    v * v * v <= table_size as u64
}

/// Entries of a level of `resolution` cells per axis: min((res+1)³, table_size).
fn level_entries(resolution: u32, table_size: usize) -> usize {
    if is_dense(resolution, table_size) {
        (resolution as usize + 1).pow(3)
    } else {
        table_size
    }
}

/// Encodes one position. `table`: `param_count()` values; `pos` in [0,1]³ (clamped);
/// `out`: `output_dim()` values, `out[level · F + f]`.
pub fn encode<R: Real>(grid: &HashGrid, table: &[R], pos: [R; 3], out: &mut [R]) {
    let f = grid.features;
    for level in 0..grid.levels {
        let level_out = &mut out[level * f..(level + 1) * f];
        level_out.fill(R::ZERO);
        for corner in grid.corners(level, pos) {
            for (o, t) in level_out.iter_mut().zip(&table[corner.offset..corner.offset + f]) {
                *o += corner.weight * *t;
            }
        }
    }
}

/// Vector-Jacobian product of `encode`: adds `∂L/∂table` to `table_grad` (`param_count()`
/// values) given `grad_out = ∂L/∂out` (`output_dim()` values). Colliding corners add up.
pub fn backward<R: Real>(grid: &HashGrid, pos: [R; 3], grad_out: &[R], table_grad: &mut [R]) {
    let f = grid.features;
    for level in 0..grid.levels {
        let level_grad = &grad_out[level * f..(level + 1) * f];
        for corner in grid.corners(level, pos) {
            for (t, g) in table_grad[corner.offset..corner.offset + f].iter_mut().zip(level_grad) {
                *t += corner.weight * *g;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::reference::gradcheck::{assert_close, central_differences, random_vec};
    use crate::rng::SplitMix64;

    /// A grid with dense coarse levels and hashed fine levels, small enough to check every entry.
    fn tiny_grid() -> HashGrid {
        HashGrid::new(4, 2, 6, 2, 2.0)
    }

    #[test]
    fn resolutions_and_dense_levels() {
        let g = tiny_grid();
        assert_eq!(g.resolutions, vec![2, 4, 8, 16]);
        assert!(g.is_dense(0) && !g.is_dense(1)); // 27 ≤ 64 < 125
        let default = HashGrid::from_config(&FieldConfig::default());
        assert_eq!(default.resolutions[15], 16 << 15);
        assert!(default.is_dense(2) && !default.is_dense(3)); // 65³ ≤ 2^19 < 129³
    }

    #[test]
    fn dense_levels_hold_their_vertices_and_hashed_levels_the_table() {
        let g = tiny_grid();
        assert_eq!(g.level_offsets, vec![0, 27, 91, 155, 219]);
        assert_eq!(g.param_count(), 219 * 2);
        assert_eq!(
            (0..4).map(|l| g.level_entries(l)).collect::<Vec<_>>(),
            vec![27, 64, 64, 64]
        );
        assert_eq!(
            [0, 53, 54, 181, 182, 437].map(|i| g.level_of_value(i)),
            [0, 0, 1, 1, 2, 3]
        );
        // A dense grid exactly the table's size is dense, and holds the whole table.
        let exact = HashGrid::new(2, 1, 12, 15, 2.0);
        assert!(exact.is_dense(0) && !exact.is_dense(1));
        assert_eq!(exact.level_offsets, vec![0, 4096, 8192]);
        // The default: 17³ + 33³ + 65³ dense entries, then 13 tables of 2^19.
        let default = HashGrid::from_config(&FieldConfig::default());
        assert_eq!(default.level_offsets[3], 4913 + 35_937 + 274_625);
        assert_eq!(default.param_count(), (315_475 + 13 * (1 << 19)) * 2);
        // Every corner of every level lands inside its own level.
        let mut rng = SplitMix64::new(4);
        for _ in 0..200 {
            let p = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
            for level in 0..g.levels {
                for c in g.corners(level, p) {
                    let entry = c.offset / g.features;
                    assert!((g.level_offsets[level]..g.level_offsets[level + 1]).contains(&entry));
                }
            }
        }
    }

    #[test]
    fn interpolates_table_values_at_vertices_and_between() {
        let g = tiny_grid();
        let mut rng = SplitMix64::new(1);
        let table: Vec<f64> = random_vec(&mut rng, g.param_count(), 1.0);
        let mut out = vec![0.0; g.output_dim()];
        // Level 0 has 2 cells per axis: p = 0.5 is vertex (1,1,1), dense entry 1 + 3 + 9 = 13.
        encode(&g, &table, [0.5, 0.5, 0.5], &mut out);
        assert_eq!(&out[0..2], &table[26..28]);
        // Halfway along x between vertices (0,0,0) and (1,0,0) of level 0.
        encode(&g, &table, [0.25, 0.0, 0.0], &mut out);
        assert!((out[0] - 0.5 * (table[0] + table[2])).abs() < 1e-12);
        // p = 1 on the last cell: weight 1 on the last vertex, nothing outside the grid.
        encode(&g, &table, [1.0, 1.0, 1.0], &mut out);
        assert_eq!(out[0], table[26 * 2]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let g = tiny_grid();
        let mut rng = SplitMix64::new(2);
        let table: Vec<f64> = random_vec(&mut rng, g.param_count(), 1.0);
        let probe: Vec<f64> = random_vec(&mut rng, g.output_dim(), 1.0);
        let positions: Vec<[f64; 3]> = (0..5)
            .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
            .collect();
        let loss = |t: &[f64]| {
            let mut out = vec![0.0; g.output_dim()];
            let mut sum = 0.0;
            for &p in &positions {
                encode(&g, t, p, &mut out);
                sum += out.iter().zip(&probe).map(|(o, w)| o * w).sum::<f64>();
            }
            sum
        };
        let mut analytic = vec![0.0; g.param_count()];
        for &p in &positions {
            backward(&g, p, &probe, &mut analytic);
        }
        let numeric = central_differences(loss, &table, 1e-6);
        assert_close("hash grid table", &analytic, &numeric, 1e-8);
    }
}
