//! # System identification: the friction label pipeline and static-model fitting
//!
//! What it is:
//! - [`kalman`]: constant-acceleration Kalman filter and RTS smoother for ṡ, s̈.
//!
//! What it is not: network training (see [`crate::train`]) or anything real-time.

pub mod dataset;
pub mod fit;
pub mod kalman;
pub mod preprocess;
