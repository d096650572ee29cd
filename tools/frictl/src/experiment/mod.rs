//! # The paper's closed-loop experiments on the virtual joints
//!
//! What this module **is**: the high-level computed-torque controller ([`controller`]) as a real
//! process role — it reads `JointStates` over shared memory and publishes `TorqueRequest` (and
//! `SimDisturbance`) in lockstep with the virtual plant (`frictl sim serve`) and `frictiond`, both
//! started as child processes per trial ([`session`], [`run`]); metrics ([`metrics`]), the
//! minimum-K_p bisection ([`search`]), the three experiments of the paper (`track`, `min-kp`,
//! `disturbance`, in [`suite`]) and their tables, JSON and plots ([`report`]); the `oracle`
//! diagnostic ([`oracle`]: compensation with the plant's true friction — a bound, not a model).
//!
//! What it is **not**: no physics (that is [`frictionless_sim`] in the plant process), no friction model
//! evaluation (that is `frictiond`); this process only controls, disturbs and measures.

pub mod controller;
pub mod metrics;
pub mod oracle;
pub mod report;
pub mod run;
pub mod search;
pub mod session;
pub mod suite;
