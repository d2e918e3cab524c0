//! Real spherical harmonics up to degree 4 (16 coefficients) of a unit view direction, with
//! tiny-cuda-nn's constants and signs. tiny-cuda-nn maps its [0,1] input to [-1,1] first;
//! here the input already is the unit direction. Directions are data, so there is no backward.
use super::real::Real;

pub const SH_COEFFS: usize = 16;

/// `dir`: unit vector; `out`: 16 values.
// The constants are tiny-cuda-nn's, digit for digit, so they can be compared with its source.
#[allow(clippy::excessive_precision)]
pub fn encode<R: Real>(dir: [R; 3], out: &mut [R]) {
    let [x, y, z] = dir;
    let c = R::of;
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (x2, y2, z2) = (x * x, y * y, z * z);
    out[0] = c(0.28209479177387814);
    out[1] = -c(0.48860251190291987) * y;
    out[2] = c(0.48860251190291987) * z;
    out[3] = -c(0.48860251190291987) * x;
    out[4] = c(1.0925484305920792) * xy;
    out[5] = -c(1.0925484305920792) * yz;
    out[6] = c(0.94617469575755997) * z2 - c(0.31539156525251999);
    out[7] = -c(1.0925484305920792) * xz;
    out[8] = c(0.54627421529603959) * x2 - c(0.54627421529603959) * y2;
    out[9] = c(0.59004358992664352) * y * (c(-3.0) * x2 + y2);
    out[10] = c(2.8906114426405538) * xy * z;
    out[11] = c(0.45704579946446572) * y * (c(1.0) - c(5.0) * z2);
    out[12] = c(0.3731763325901154) * z * (c(5.0) * z2 - c(3.0));
    out[13] = c(0.45704579946446572) * x * (c(1.0) - c(5.0) * z2);
    out[14] = c(1.4453057213202769) * z * (x2 - y2);
    out[15] = c(0.59004358992664352) * x * (-x2 + c(3.0) * y2);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The basis is orthonormal on the sphere: 4π·E[Y_i Y_j] = δ_ij under uniform directions.
    /// A wrong constant or sign pattern breaks this, so it checks all 16 formulas at once.
    #[test]
    fn basis_is_orthonormal() {
        let mut rng = SplitMix64::new(5);
        let n = 40_000;
        let mut gram = [[0.0f64; SH_COEFFS]; SH_COEFFS];
        let mut y = [0.0f64; SH_COEFFS];
        for _ in 0..n {
            let z = rng.uniform(-1.0, 1.0);
            let phi = rng.uniform(0.0, std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            encode([r * phi.cos(), r * phi.sin(), z], &mut y);
            for i in 0..SH_COEFFS {
                for j in 0..SH_COEFFS {
                    gram[i][j] += y[i] * y[j];
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                let v = g * 4.0 * std::f64::consts::PI / n as f64;
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!((v - expect).abs() < 0.06, "<Y{i}, Y{j}> = {v}");
            }
        }
    }
}
