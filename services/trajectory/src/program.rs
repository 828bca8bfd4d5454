//! Motion programs (placeholder).
