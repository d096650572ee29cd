//! Fuzz target: arbitrary bytes into the `.fwt` reader and the header inspector.
//!
//! Both must return (never panic, never allocate unboundedly). Beyond that it checks two properties:
//! whatever `from_bytes` accepts, `inspect` accepts as valid; a file of the minor version the writer
//! writes that `from_bytes` accepts is re-encoded by `to_bytes` to exactly the same bytes (the format
//! is canonical); and an accepted older-minor file re-encodes to a file that decodes to the same model (same encoding: NaN-safe).
#![no_main]

use frictionless::weights::layout::VERSION_MINOR;
use frictionless::weights::{from_bytes, inspect, to_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    check(data);
    // Most mutations break the CRC; also feed the same bytes with a correct CRC so the checks
    // behind it (reserved bytes, values, names, finiteness) are reached.
    if data.len() >= 16 {
        let mut fixed = data.to_vec();
        fixed[12..16].fill(0);
        let crc = crc32c::crc32c(&fixed);
        fixed[12..16].copy_from_slice(&crc.to_le_bytes());
        check(&fixed);
    }
});

fn check(data: &[u8]) {
    let decoded = from_bytes(data);
    let view = inspect(data);
    if let Ok(model) = &decoded {
        let v = view
            .as_ref()
            .expect("inspect must accept what from_bytes accepts");
        assert!(
            v.crc_ok && v.error.is_none(),
            "accepted file must inspect as valid"
        );
        if v.version_minor <= VERSION_MINOR {
            let again = to_bytes(model).expect("an accepted model must re-encode");
            if v.version_minor == VERSION_MINOR {
                assert!(
                    again == data,
                    "re-encoding an accepted file of the current minor must reproduce it"
                );
            } else {
                let back = from_bytes(&again).expect("the re-encoded older file must decode");
                // Compared as encodings, not with `==`: a NaN the format allows (e.g. in a
                // prior parameter) is never `==` to itself, though it round-trips bit for bit.
                assert!(
                    to_bytes(&back).expect("re-encode") == again,
                    "an older-minor file re-encodes to the same model"
                );
            }
        }
    }
    if let Ok(v) = &view {
        let _ = v.to_string();
        let _ = serde_json::to_string(v).expect("Inspection serialises");
    }
}
