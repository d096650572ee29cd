//! Fuzz target: arbitrary bytes into the ONNX importer (`frictionless_interop::onnx::import_bytes`:
//! protobuf decoding, graph walk, MLP pattern match, folded normalisation) and the safetensors
//! importer. Both must return a model or an error, never panic; an imported ONNX model's weights
//! must convert to a `.fwt` the core reader accepts or be refused by the writer with an error.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = frictionless_interop::onnx::import_bytes(data);
    let _ = frictionless_interop::safetensors::import_bytes(data);
});
