//! # System identification: the friction label pipeline and static-model fitting
//!
//! What it is:
//! - [`filter`]: Butterworth low-pass as second-order sections, causal and zero-phase, equal to scipy;
//! - [`kalman`]: constant-acceleration Kalman filter and RTS smoother for ṡ, s̈;
//! - [`fit_file`]: the JSON of `frictl fit --json` (written by `frictl fit`, read by eval, train,
//!   experiment and the demo).
//!
//! What it is not: network training (see [`crate::train`]) or anything real-time.

pub mod dataset;
pub mod filter;
pub mod fit;
pub mod fit_file;
pub mod kalman;
pub mod preprocess;
