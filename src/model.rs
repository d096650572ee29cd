//! none / CV / SCV / PINN behind one trait.
//!
//! (skeleton)
