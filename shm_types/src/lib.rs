//! The ABI between processes (skeleton).
