//! Cache warming for the real-time path: walks a network's weight store (every storage dtype) and
//! its biases one 64-byte line at a time so the next inference finds them in cache.
//!
//! What this module **is**: [`Mlp::prefetch`], called by a real-time loop in the idle part of its
//! period (after publishing a tick, or shortly before the next deadline) so weights that the rest of
//! the machine evicted come back from memory before the tick needs them rather than during it. On
//! x86-64 each line gets a `prefetcht1` hint (into L2 and outward; no register is written, the call
//! returns before the lines arrive); elsewhere each line is read once with a volatile load.
//!
//! What it is **not**: no inference, no allocation, no writes to the network; it changes only which
//! lines the caches hold.

use super::{Block, HalfBlock, Mlp};

/// Bytes per cache line (the stores are 64-byte aligned, one [`Block`] / [`HalfBlock`] per line).
const LINE: usize = 64;

/// Touches every cache line of `bytes` bytes from `start`.
#[inline]
fn touch_lines(start: *const u8, bytes: usize) {
    let mut off = 0;
    while off < bytes {
        // SAFETY: `start + off` lies inside the slice the caller passed (`off < bytes`).
        let p = unsafe { start.add(off) };
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_MM_HINT_T1, _mm_prefetch};
            // SAFETY: a prefetch hint never faults and reads no register-visible memory.
            unsafe { _mm_prefetch::<_MM_HINT_T1>(p.cast()) };
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            // SAFETY: `p` points into a live, initialised slice.
            unsafe { std::ptr::read_volatile(p) };
        }
        off += LINE;
    }
}

#[inline]
fn touch<T>(v: &[T]) {
    touch_lines(v.as_ptr().cast(), std::mem::size_of_val(v));
}

// The walk assumes one store element per cache line.
const _: () =
    assert!(std::mem::size_of::<Block>() == LINE && std::mem::size_of::<HalfBlock>() == LINE);

impl Mlp {
    /// Brings this network's weights and biases towards the core (`prefetcht1` per 64-byte line on
    /// x86-64, a read per line elsewhere): every byte range of the weight store (`Net::weight_spans`,
    /// whatever the storage dtype), then the biases.
    /// Allocation-free, lock-free, never panics; does not change any result.
    #[inline]
    pub fn prefetch(&self) {
        for span in self.net.weight_spans() {
            touch(span);
        }
        touch(&self.net.bias);
    }
}

#[cfg(test)]
mod tests {
    use crate::kernel::Mlp;
    use crate::mlp::StorageDtype;
    use crate::random::{RandomMlpSpec, seeded_mlp};

    #[test]
    fn prefetch_walks_every_dtype_and_changes_no_result() {
        let w = seeded_mlp(&RandomMlpSpec::new(&[6, 40, 33, 1]), 3).unwrap();
        let x = [0.1, -0.2, 0.3, 0.05, -0.4, 0.2];
        for dtype in StorageDtype::ALL {
            let mut m = Mlp::new(&w, dtype).unwrap();
            let before = m.forward(&x);
            m.prefetch();
            assert_eq!(m.forward(&x).to_bits(), before.to_bits(), "{dtype:?}");
        }
    }
}
