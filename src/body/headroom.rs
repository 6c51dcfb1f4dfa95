//! Room to grow, written in advance. A body that may crack reserves it in the arrays that a
//! topology change rebuilds or grows (vertices, springs, the solver's per-vertex buffers and
//! coupling layout, the gas's corner lists), so that a cracking step within that room moves
//! no array and faults in no fresh page: a reallocation copies the old contents, and new
//! memory faults its pages in one by one on first use. On the issue-5 balloon's first cracking
//! step (benches/body_balloon.rs, 301 springs) the rebuilds made about 900 page faults.

/// Gives `v` a capacity of at least `room` elements, its memory written once past its length
/// (`resize`, then `truncate`: `vec![0; n]` would not touch fresh pages), its contents kept.
pub(crate) fn reserve_written<T: Copy + Default>(v: &mut Vec<T>, room: usize) {
    if v.capacity() >= room {
        return;
    }
    let len = v.len();
    let mut roomy = Vec::with_capacity(room);
    roomy.extend_from_slice(v);
    roomy.resize(room, T::default());
    roomy.truncate(len);
    *v = roomy;
}

/// [`reserve_written`] with room for a fraction `headroom` more than `len` elements.
pub(crate) fn reserve_for<T: Copy + Default>(v: &mut Vec<T>, len: usize, headroom: f64) {
    reserve_written(v, len + (len as f64 * headroom).ceil() as usize);
}

/// [`reserve_for`] `v`'s own length.
pub(crate) fn with_room<T: Copy + Default>(v: &mut Vec<T>, headroom: f64) {
    reserve_for(v, v.len(), headroom);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_room_is_reserved_and_the_contents_kept() {
        let mut v = vec![1u32, 2, 3, 4];
        with_room(&mut v, 0.5);
        assert_eq!(v, [1, 2, 3, 4]);
        assert!(v.capacity() >= 6);
        let address = v.as_ptr();
        v.extend([5, 6]);
        assert_eq!(v.as_ptr(), address, "growth within the room moves nothing");
        let mut empty: Vec<f64> = Vec::new();
        reserve_for(&mut empty, 8, 0.125);
        assert!(empty.is_empty() && empty.capacity() >= 9);
        // Enough room already: nothing changes.
        let capacity = v.capacity();
        reserve_written(&mut v, 3);
        assert_eq!((v.capacity(), v.as_ptr()), (capacity, address));
    }
}
