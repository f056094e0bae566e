//! Analytic phantoms (placeholder; being written).
