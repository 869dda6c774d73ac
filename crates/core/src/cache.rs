//! Software prefetch: a hint to bring a value's cache line closer before it is used (the gradient replay's adds,
//! queued a few adds ahead). A hint only: it changes no value the program sees, so no result's bits.

/// Fetch the cache line of `x`, about to be written, into the nearest cache (x86-64's PREFETCHW; a no-op on CPUs
/// without it and on other architectures).
#[inline(always)]
pub fn prefetch_write<T>(x: &T) {
    // SAFETY: a prefetch only hints the caches: it changes no state the program sees and cannot fault.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        core::arch::x86_64::_mm_prefetch::<{ core::arch::x86_64::_MM_HINT_ET0 }>(x as *const T as *const i8)
    };
}
