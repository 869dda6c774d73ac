//! Giving memory back to the system while its owner still holds it: a big buffer read one block at a time and
//! then no longer needed (a gradient buffer's fixed-point sums as they are converted) need not stay resident until
//! the whole buffer is dropped.

use std::sync::atomic::AtomicI64;

/// Give the whole memory pages inside `s` back to the system: afterwards they read as zeros and take no memory
/// until written again (Linux: `madvise(MADV_DONTNEED)` on the allocator's private anonymous memory, the same as
/// writing zeros to them). The partial pages at either end keep their values. A no-op on other systems, and when
/// the system refuses (the values are then unchanged). Returns the bytes given back.
pub fn release(s: &mut [AtomicI64]) -> usize {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: sysconf only reads a system setting.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
        let page = if page > 0 { page as usize } else { return 0 };
        let (start, end) = (s.as_mut_ptr() as usize, s.as_mut_ptr() as usize + std::mem::size_of_val(s));
        let (a, b) = (start.div_ceil(page) * page, end / page * page);
        if b <= a {
            return 0;
        }
        // SAFETY: [a, b) lies inside `s`, which this function borrows mutably, so nothing else reads or writes it
        // meanwhile; the pages come back as zeros, a valid AtomicI64 value, as if zeros had been stored.
        let done = unsafe { libc::madvise(a as *mut libc::c_void, b - a, libc::MADV_DONTNEED) };
        if done == 0 {
            b - a
        } else {
            0
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = s;
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::Ordering::Relaxed;

    /// The whole pages inside the slice read as zeros after `release`, the values on the partial pages at its
    /// ends and outside it are unchanged, and the bytes given back are those pages (Linux).
    #[test]
    fn release_zeroes_whole_pages_and_keeps_the_rest() {
        let n = 1 << 16;
        let mut v: Vec<AtomicI64> = (0..n).map(|i| AtomicI64::new(i as i64 + 1)).collect();
        let (lo, hi) = (1000, n - 3000);
        let given = release(&mut v[lo..hi]);
        if !cfg!(target_os = "linux") {
            assert_eq!(given, 0);
            return;
        }
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) } as usize;
        let base = v.as_ptr() as usize;
        let addr = |i: usize| base + 8 * i;
        let (a, b) = (addr(lo).div_ceil(page) * page, addr(hi) / page * page);
        assert!(b > a && given == b - a, "{given} bytes given back, pages [{a}, {b})");
        for (i, x) in v.iter().enumerate() {
            let zeroed = addr(i) >= a && addr(i) < b;
            assert_eq!(x.load(Relaxed), if zeroed { 0 } else { i as i64 + 1 }, "slot {i}");
        }
    }
}
