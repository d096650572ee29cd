//! Integration tests of `frictionless-interop` (ONNX and safetensors import/export, reference vectors).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod interop_onnx;
mod interop_refs;
mod interop_safetensors;
