//! Finite-difference helpers for the gradient tests (f64 central differences).
use crate::rng::SplitMix64;

/// Central differences `(f(x + h·e_i) − f(x − h·e_i)) / 2h` for every coordinate.
pub fn central_differences(f: impl Fn(&[f64]) -> f64, x: &[f64], h: f64) -> Vec<f64> {
    let mut probe = x.to_vec();
    (0..x.len())
        .map(|i| {
            probe[i] = x[i] + h;
            let up = f(&probe);
            probe[i] = x[i] - h;
            let down = f(&probe);
            probe[i] = x[i];
            (up - down) / (2.0 * h)
        })
        .collect()
}

/// Largest absolute difference, relative to the largest numeric gradient component:
/// `max_i |a_i − n_i| / max_i |n_i|`. Scale-free, and not fooled by components that are
/// zero in both (unlike a per-component relative error).
pub fn relative_error(analytic: &[f64], numeric: &[f64]) -> f64 {
    assert_eq!(analytic.len(), numeric.len());
    let scale = numeric.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = analytic
        .iter()
        .zip(numeric)
        .fold(0.0f64, |m, (a, n)| m.max((a - n).abs()));
    diff / scale.max(1e-300)
}

/// Asserts the relative error is below `tolerance` and that the gradient is not trivially
/// zero (a test comparing two zero vectors proves nothing); prints the level measured.
pub fn assert_close(what: &str, analytic: &[f64], numeric: &[f64], tolerance: f64) {
    let scale = numeric.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        scale > 1e-8,
        "{what}: numeric gradient is all zero; the check proves nothing"
    );
    let err = relative_error(analytic, numeric);
    eprintln!(
        "finite differences: {what}: relative error {err:.2e} over {} values",
        analytic.len()
    );
    assert!(
        err < tolerance,
        "{what}: relative error {err:.3e} above {tolerance:.1e}"
    );
}

pub fn random_vec(rng: &mut SplitMix64, n: usize, scale: f64) -> Vec<f64> {
    (0..n).map(|_| rng.uniform(-scale, scale)).collect()
}
