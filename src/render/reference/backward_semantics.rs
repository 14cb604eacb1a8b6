//! The semantic vector `s` a Gaussian blends (its logits, or their softmax) and the
//! gradient of the logits given the gradient of `s`.

use super::SemanticMode;

/// `s` for one Gaussian's logits, computed exactly as the forward renderer does.
pub(super) fn semantic_vector(logits: &[f64], mode: SemanticMode) -> Vec<f64> {
    match mode {
        SemanticMode::RawLogits => logits.to_vec(),
        SemanticMode::Softmax => {
            let max = logits.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let exps: Vec<f64> = logits.iter().map(|v| (v - max).exp()).collect();
            let total: f64 = exps.iter().sum();
            exps.iter().map(|e| e / total).collect()
        }
    }
}

/// `dL/dlogits` from `dL/ds`, where `s = semantic_vector(logits, mode)`.
pub(super) fn semantic_vector_grad(s: &[f64], grad_s: &[f64], mode: SemanticMode) -> Vec<f64> {
    match mode {
        SemanticMode::RawLogits => grad_s.to_vec(),
        // ds_j/dl_k = s_j (delta_jk - s_k), so dL/dl_k = s_k (g_k - sum_j g_j s_j).
        SemanticMode::Softmax => {
            let mean: f64 = s.iter().zip(grad_s).map(|(s, g)| s * g).sum();
            s.iter().zip(grad_s).map(|(s, g)| s * (g - mean)).collect()
        }
    }
}
