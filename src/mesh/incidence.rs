//! Vertex-to-primitive incidence in compressed rows (CSR), for the per-vertex gathers and the
//! neighbour lookups of the simulators.

/// For each of `vertex_count` vertices, the entries `entry(primitive, corner)` of every corner of
/// `prims` at that vertex, in primitive order: the entries of vertex v are
/// `list[offsets[v]..offsets[v + 1]]`. Returns `(offsets, list)`. A vertex repeated within one
/// primitive is listed once per corner.
pub(crate) fn vertex_incidence<const N: usize>(
    vertex_count: usize,
    prims: &[[u32; N]],
    entry: impl Fn(usize, usize) -> u32,
) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; vertex_count + 1];
    for prim in prims {
        for &v in prim {
            offsets[v as usize + 1] += 1;
        }
    }
    for v in 0..vertex_count {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor = offsets.clone();
    let mut list = vec![0u32; offsets[vertex_count] as usize];
    for (i, prim) in prims.iter().enumerate() {
        for (corner, &v) in prim.iter().enumerate() {
            list[cursor[v as usize] as usize] = entry(i, corner);
            cursor[v as usize] += 1;
        }
    }
    (offsets, list)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_each_vertex_primitives_in_order() {
        let tris = [[0, 1, 2], [2, 1, 3]];
        let (offsets, faces) = vertex_incidence(4, &tris, |f, _| f as u32);
        assert_eq!(offsets, vec![0, 1, 3, 5, 6]);
        assert_eq!(faces, vec![0, 0, 1, 0, 1, 1]);
        let (_, corners) = vertex_incidence(4, &tris, |f, c| 3 * f as u32 + c as u32);
        assert_eq!(corners, vec![0, 1, 4, 2, 3, 5]);
    }
}
