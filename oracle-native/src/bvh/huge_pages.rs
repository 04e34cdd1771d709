//! Huge pages for the tree's memory. A ray through a tree of tens of
//! megabytes touches a new 4 KiB page at most nodes and blocks it visits,
//! and each costs a walk of the page tables; in 2 MiB pages the TLB covers
//! the whole tree. Linux backs memory with huge pages where a program asks
//! (`madvise(MADV_HUGEPAGE)`, transparent huge pages in their default
//! `madvise` mode), as Embree asks for its trees' memory.

/// Reserves room for `additional` more items in `items`, asking the kernel
/// to back the room with huge pages (Linux; elsewhere, or where the kernel
/// declines, the ordinary pages). A hint: what the items hold is the same.
pub(super) fn reserve<T>(items: &mut Vec<T>, additional: usize) {
    items.reserve_exact(additional);
    #[cfg(target_os = "linux")]
    advise(items);
}

#[cfg(target_os = "linux")]
fn advise<T>(items: &mut Vec<T>) {
    const HUGE_PAGE: usize = 2 << 20;
    // SAFETY: sysconf reads a constant of the system.
    #[allow(unsafe_code)]
    let page = match unsafe { libc::sysconf(libc::_SC_PAGESIZE) } {
        size if size > 0 => size as usize,
        _ => return,
    };
    let start = items.as_ptr() as usize;
    let end = start + items.capacity() * core::mem::size_of::<T>();
    // The whole pages inside the vector's buffer, all of them its own.
    let (first, last) = (start.next_multiple_of(page), end / page * page);
    if last < first + HUGE_PAGE {
        return;
    }
    let at = items.as_mut_ptr().cast::<u8>().wrapping_add(first - start);
    // SAFETY: the range is whole pages of the vector's own allocation, and
    // the advice changes how the kernel backs them, never what they hold;
    // an error (an old kernel, huge pages disabled) leaves them as they are.
    #[allow(unsafe_code)]
    unsafe {
        libc::madvise(at.cast(), last - first, libc::MADV_HUGEPAGE);
    }
}

#[cfg(test)]
mod tests {
    /// Room reserved in huge pages (more than one: 8 MiB) after items
    /// already held keeps them, and takes new ones.
    #[test]
    fn reserving_keeps_what_the_vector_holds() {
        let mut items: Vec<u64> = (0..1000).collect();
        super::reserve(&mut items, 1 << 20);
        assert!(items.capacity() >= 1000 + (1 << 20));
        items.extend(1000..(1 << 20) + 1000);
        assert!(items.iter().enumerate().all(|(i, &v)| v == i as u64));
    }
}
