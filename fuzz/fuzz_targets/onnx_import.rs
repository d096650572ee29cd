//! Fuzz target: arbitrary bytes into the ONNX importer (`frictionless_interop::onnx::import_bytes`:
//! protobuf decoding, graph walk, MLP pattern match, folded normalisation) and the safetensors
//! importer. Both must return a model or an error, never panic and never allocate beyond what the
//! input's own tensors hold.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = frictionless_interop::onnx::import_bytes(data);
    let _ = frictionless_interop::safetensors::import_bytes(data);
});
