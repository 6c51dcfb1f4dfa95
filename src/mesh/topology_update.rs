//! [`Topology::update`]: brings a topology up to date after some faces changed corners (or were
//! appended), touching only what those faces reach, with the same result as a new build.
//!
//! The fracture (SPEC 2.4) re-instances a few hundred corners of a 20k-face surface per cracking
//! step; building the whole topology again cost most of the crack phase.

use super::{NO_FACE, Topology};

/// An edge whose faces were looked up again: its key, how many faces use it, the first two and
/// whether two faces run along it the same way; its half-edges are `members[range]`.
struct Group {
    key: [u32; 2],
    count: u32,
    faces: [u32; 2],
    inconsistent: bool,
    members: std::ops::Range<usize>,
}

/// The distinct corners of a triangle (a repeated corner once, in corner order).
fn distinct(t: [u32; 3]) -> impl Iterator<Item = u32> {
    (0..3).filter(move |&c| !t[..c].contains(&t[c])).map(move |c| t[c])
}

/// The undirected sides of a triangle whose ends differ, as `(min, max)`.
fn sides(t: [u32; 3]) -> impl Iterator<Item = [u32; 2]> {
    (0..3).map(move |s| (t[s], t[(s + 1) % 3])).filter(|(a, b)| a != b).map(|(a, b)| [a.min(b), a.max(b)])
}

/// `slice.binary_search(key)` for a key expected near the start of the sorted `slice`: doubling
/// steps from the start bracket it, then a binary search inside the bracket. The merge below
/// looks up a sorted list of keys in the sorted edges, each from where the last one was found,
/// so the next key is usually a few edges on; a plain binary search over the rest of the 30k
/// edges of the issue-5 balloon made about 15 scattered loads per key. On that balloon's first
/// cracking step (276 springs) the merge took 0.44 ms before and 0.12-0.39 ms after (one run
/// each; this machine's timings of sub-millisecond phases vary by 2x or more).
fn search_from<T: Ord>(slice: &[T], key: &T) -> Result<usize, usize> {
    let mut end = 1;
    while end < slice.len() && slice[end - 1] < *key {
        end *= 2;
    }
    let start = end / 2;
    let end = end.min(slice.len());
    match slice[start..end].binary_search(key) {
        Ok(i) => Ok(start + i),
        Err(i) => Err(start + i),
    }
}

impl Topology {
    /// Updates the topology of `old_triangles` (which it describes) to `triangles`: the same
    /// faces, some with other corners, possibly more faces appended, over `vertex_count`
    /// vertices (no fewer than before). The result is identical to `Topology::build(triangles,
    /// vertex_count)`; the work grows with the number of changed faces, apart from a few linear
    /// passes (renumbering the face edges, the boundary loops and the components).
    pub fn update(&mut self, old_triangles: &[[u32; 3]], triangles: &[[u32; 3]], vertex_count: usize) {
        let old_vertex_count = self.vertex_face_offsets.len().saturating_sub(1);
        if triangles.len() < old_triangles.len()
            || self.face_edges.len() != old_triangles.len()
            || self.vertex_face_offsets.is_empty()
            || vertex_count < old_vertex_count
        {
            *self = Topology::build(triangles, vertex_count);
            return;
        }
        let old_face_count = old_triangles.len();
        let changed: Vec<u32> = (0..triangles.len())
            .filter(|&f| f >= old_face_count || old_triangles[f] != triangles[f])
            .map(|f| f as u32)
            .collect();
        let old_corners = |f: u32| (f as usize) < old_face_count;
        let touched = self.update_vertex_faces(old_triangles, triangles, vertex_count, &changed);

        // Edges whose faces may have changed: every side of a changed face, before and after.
        let mut keys: Vec<[u32; 2]> = Vec::new();
        for &f in &changed {
            if old_corners(f) {
                keys.extend(sides(old_triangles[f as usize]));
            }
            keys.extend(sides(triangles[f as usize]));
        }
        keys.sort_unstable();
        keys.dedup();
        // Their half-edges now, found around the smaller vertex, in (face, side) order.
        let mut members: Vec<(u32, u8)> = Vec::new();
        let mut groups: Vec<Group> = Vec::with_capacity(keys.len());
        for &key in &keys {
            let first = members.len();
            for &g in self.faces_of_vertex(key[0]) {
                let t = triangles[g as usize];
                for s in 0..3 {
                    let (a, b) = (t[s], t[(s + 1) % 3]);
                    if a != b && [a.min(b), a.max(b)] == key {
                        members.push((g, s as u8));
                    }
                }
            }
            let group = &members[first..];
            if group.is_empty() {
                continue;
            }
            let forward = |&(g, s): &(u32, u8)| triangles[g as usize][s as usize] == key[0];
            groups.push(Group {
                key,
                count: group.len() as u32,
                faces: [group[0].0, group.get(1).map_or(NO_FACE, |h| h.0)],
                inconsistent: group.len() == 2 && forward(&group[0]) == forward(&group[1]),
                members: first..members.len(),
            });
        }

        // Merge the kept edges with the regrouped ones (both sorted by key), copying the runs of
        // kept edges between regrouped keys at once; `index` maps an old edge to its new index
        // (u32::MAX for a regrouped or vanished one).
        let old_edge_count = self.edges.len();
        let capacity = old_edge_count + groups.len();
        let mut index = vec![u32::MAX; old_edge_count];
        let mut edges = Vec::with_capacity(capacity);
        let mut edge_faces = Vec::with_capacity(capacity);
        let mut edge_face_count = Vec::with_capacity(capacity);
        let mut group_index = Vec::with_capacity(groups.len());
        let mut inconsistent = Vec::new();
        let mut copied = 0; // old edges before this are placed
        let mut k = 0; // next group
        for key in keys.iter().copied().chain(std::iter::once([u32::MAX; 2])) {
            let (at, found) = match search_from(&self.edges[copied..], &key) {
                Ok(i) => (copied + i, true),
                Err(i) => (copied + i, false),
            };
            let start = edges.len() as u32;
            for (slot, new) in index[copied..at].iter_mut().zip(start..) {
                *slot = new;
            }
            edges.extend_from_slice(&self.edges[copied..at]);
            edge_faces.extend_from_slice(&self.edge_faces[copied..at]);
            edge_face_count.extend_from_slice(&self.edge_face_count[copied..at]);
            copied = if found { at + 1 } else { at };
            if k < groups.len() && groups[k].key == key {
                let group = &groups[k];
                let new = edges.len() as u32;
                group_index.push(new);
                edges.push(group.key);
                edge_faces.push(group.faces);
                edge_face_count.push(group.count);
                if group.inconsistent {
                    inconsistent.push(new);
                }
                k += 1;
            }
        }
        inconsistent.extend(self.inconsistent_edges.iter().map(|&e| index[e as usize]).filter(|&e| e != u32::MAX));
        inconsistent.sort_unstable();
        edges.shrink_to_fit();
        edge_faces.shrink_to_fit();
        edge_face_count.shrink_to_fit();
        self.edges = edges;
        self.edge_faces = edge_faces;
        self.edge_face_count = edge_face_count;
        self.inconsistent_edges = inconsistent;

        // Face edges: renumber, then the regrouped edges' half-edges (all sides of the changed
        // faces among them) take their new index.
        self.face_edges.resize(triangles.len(), [u32::MAX; 3]);
        for sides in &mut self.face_edges {
            for e in sides.iter_mut().filter(|e| **e != u32::MAX) {
                *e = index[*e as usize];
            }
        }
        for &f in &changed {
            self.face_edges[f as usize] = [u32::MAX; 3];
        }
        for (group, &new) in groups.iter().zip(&group_index) {
            for &(g, s) in &members[group.members.clone()] {
                self.face_edges[g as usize][s as usize] = new;
            }
        }

        // Fans change only at the ends of the regrouped edges and where the faces changed.
        let mut again: Vec<u32> = keys.iter().flatten().copied().chain(touched).collect();
        again.sort_unstable();
        again.dedup();
        let mut non_manifold: Vec<u32> = self
            .non_manifold_vertices
            .iter()
            .copied()
            .filter(|v| again.binary_search(v).is_err())
            .chain(again.iter().copied().filter(|&v| self.fan_count(triangles, v) > 1))
            .collect();
        non_manifold.sort_unstable();
        self.non_manifold_vertices = non_manifold;

        self.boundary_loops = Vec::new();
        self.build_boundary_loops(triangles);
        self.build_components(triangles, vertex_count);
    }

    /// Updates the faces around each vertex for the faces `changed`; returns the vertices whose
    /// faces changed.
    fn update_vertex_faces(
        &mut self,
        old_triangles: &[[u32; 3]],
        triangles: &[[u32; 3]],
        vertex_count: usize,
        changed: &[u32],
    ) -> Vec<u32> {
        // (vertex, face, added): faces that left or joined a vertex, sorted.
        let mut moves: Vec<(u32, u32, bool)> = Vec::new();
        for &f in changed {
            let new = triangles[f as usize];
            let old = old_triangles.get(f as usize).copied();
            if let Some(old) = old {
                moves.extend(distinct(old).filter(|v| !new.contains(v)).map(|v| (v, f, false)));
            }
            moves.extend(distinct(new).filter(|v| old.is_none_or(|old| !old.contains(v))).map(|v| (v, f, true)));
        }
        moves.sort_unstable();
        let old_vertex_count = self.vertex_face_offsets.len() - 1;
        let old_offsets = std::mem::take(&mut self.vertex_face_offsets);
        let old_faces = std::mem::take(&mut self.vertex_faces);
        let added = moves.iter().filter(|m| m.2).count();
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut faces = Vec::with_capacity(old_faces.len() + added);
        let old_range = |v: usize| {
            if v < old_vertex_count { old_offsets[v] as usize..old_offsets[v + 1] as usize } else { 0..0 }
        };
        let mut touched = Vec::new();
        let mut m = 0;
        let mut v = 0;
        while v < vertex_count {
            let next = moves.get(m).map_or(vertex_count, |mv| mv.0 as usize);
            // Untouched vertices up to the next move: one copy, offsets shifted.
            if v < next {
                let copy_end = next.min(old_vertex_count).max(v);
                if v < copy_end {
                    let shift = faces.len() as i64 - old_offsets[v] as i64;
                    offsets.extend(old_offsets[v..copy_end].iter().map(|&o| (o as i64 + shift) as u32));
                    faces.extend_from_slice(&old_faces[old_offsets[v] as usize..old_offsets[copy_end] as usize]);
                }
                // Vertices new since the old topology, without faces.
                offsets.extend(std::iter::repeat_n(faces.len() as u32, next - copy_end));
                v = next;
                continue;
            }
            // Vertex v: its old faces without those that left, merged with those that joined.
            let end = m + moves[m..].iter().take_while(|mv| mv.0 as usize == v).count();
            offsets.push(faces.len() as u32);
            let mut joined = moves[m..end].iter().filter(|mv| mv.2).map(|mv| mv.1).peekable();
            let mut left = moves[m..end].iter().filter(|mv| !mv.2).map(|mv| mv.1).peekable();
            for &f in &old_faces[old_range(v)] {
                while let Some(g) = joined.next_if(|&g| g < f) {
                    faces.push(g);
                }
                if left.next_if_eq(&f).is_none() {
                    faces.push(f);
                }
            }
            faces.extend(joined);
            touched.push(v as u32);
            m = end;
            v += 1;
        }
        offsets.push(faces.len() as u32);
        self.referenced_vertices = (0..vertex_count).filter(|&v| offsets[v + 1] > offsets[v]).count();
        self.vertex_face_offsets = offsets;
        self.vertex_faces = faces;
        touched
    }
}

#[cfg(test)]
mod tests {
    use super::search_from;

    /// The same answer as a binary search, found or not, for every key around every position
    /// of sorted slices of 0 to 40 distinct even numbers.
    #[test]
    fn search_from_agrees_with_binary_search() {
        for len in 0..40u32 {
            let slice: Vec<u32> = (0..len).map(|i| 2 * i + 2).collect();
            for key in 0..2 * len + 5 {
                assert_eq!(search_from(&slice, &key), slice.binary_search(&key), "len {len}, key {key}");
            }
        }
    }
}
