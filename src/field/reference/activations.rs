//! Output activations: density σ = exp(h₀) and the colour sigmoid.
use super::real::Real;

/// h₀ is clamped to this range before the exponential: e^15 ≈ 3.3e6 per metre is already an
/// opaque surface at any sample spacing, and the clamp keeps f32 from overflowing.
pub const DENSITY_LOG_CLAMP: f64 = 15.0;

/// σ = exp(clamp(h₀, −15, 15)).
pub fn density<R: Real>(h0: R) -> R {
    h0.clamp(R::of(-DENSITY_LOG_CLAMP), R::of(DENSITY_LOG_CLAMP)).exp()
}

/// ∂L/∂h₀ given ∂L/∂σ: instant-ngp's "truncated exponential". The derivative used is
/// exp(clamp(h₀)) everywhere, also outside the clamp where the true derivative is 0, so a
/// sample pushed to an extreme density still receives a gradient that can bring it back;
/// inside the clamp it is the exact derivative.
pub fn density_backward<R: Real>(h0: R, grad_sigma: R) -> R {
    grad_sigma * density(h0)
}

/// Colour c = 1 / (1 + e^−h).
pub fn sigmoid<R: Real>(h: R) -> R {
    R::ONE / (R::ONE + (-h).exp())
}

/// ∂L/∂h given the forward output `c = sigmoid(h)` and ∂L/∂c.
pub fn sigmoid_backward<R: Real>(c: R, grad_c: R) -> R {
    grad_c * c * (R::ONE - c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::reference::gradcheck::{assert_close, central_differences};

    #[test]
    fn gradients_match_finite_differences() {
        let hs = [-3.0, -0.7, 0.0, 0.4, 2.5, 14.0];
        let sig_analytic: Vec<f64> = hs.iter().map(|&h| sigmoid_backward(sigmoid(h), 1.0)).collect();
        let sig_numeric = central_differences(|x| x.iter().map(|&h| sigmoid(h)).sum(), &hs, 1e-6);
        assert_close("sigmoid", &sig_analytic, &sig_numeric, 1e-8);
        let den_analytic: Vec<f64> = hs.iter().map(|&h| density_backward(h, 1.0)).collect();
        let den_numeric = central_differences(|x| x.iter().map(|&h| density(h)).sum(), &hs, 1e-6);
        assert_close("density exp", &den_analytic, &den_numeric, 1e-8);
    }

    #[test]
    fn density_is_clamped_but_keeps_a_gradient() {
        assert_eq!(density(100.0f32), (15.0f32).exp());
        assert!(density(-100.0f64) > 0.0);
        assert_eq!(density_backward(40.0f64, 2.0), 2.0 * 15f64.exp());
    }
}
