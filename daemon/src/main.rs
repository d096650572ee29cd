//! `frictiond` (skeleton).
fn main() {}
