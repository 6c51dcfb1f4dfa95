//! [`Topology::update`]: brings a topology up to date after some faces changed corners (or were
//! appended), touching only what those faces reach, with the same result as a new build.
//!
//! The fracture (SPEC 2.4) re-instances a few hundred corners of a 20k-face surface per cracking
//! step; building the whole topology again cost most of the crack phase.

use super::{NO_FACE, Topology, components_into};
use crate::parallel::WorkerPool;

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

/// The buffers that [`Topology::update_with`] builds a topology's largest arrays in before it
/// swaps them with the topology's own (which become the spare of the next update), and the
/// scratch of an update.
///
/// Why: arrays allocated anew at every update cost more in first-touch page faults than the
/// update's work. On the issue-5 balloon's first cracking step (276 springs,
/// benches/body_balloon.rs) the update made 231 page faults (0.9 MB of new arrays) and took
/// 2.1-2.4 ms; 720 KB allocated and written in the same place took 0.4-0.6 ms by itself. Made by
/// [`TopologySpare::for_topology`], the buffers' memory is written when the body is made, not in
/// the step that cracks.
#[derive(Debug, Default)]
pub struct TopologySpare {
    edges: Vec<[u32; 2]>,
    edge_faces: Vec<[u32; 2]>,
    edge_face_count: Vec<u32>,
    vertex_face_offsets: Vec<u32>,
    vertex_faces: Vec<u32>,
    /// Scratch: old edge -> new edge, and the components' union-find and labels.
    index: Vec<u32>,
    parent: Vec<u32>,
    label: Vec<u32>,
    /// Scratch of the boundary loops' update: a mark per vertex, all false between updates.
    marks: Vec<bool>,
}

/// An empty vector with room for `len` elements whose memory has been written (so that filling
/// it later makes no page faults).
fn touched<T: Copy + Default>(len: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(len);
    // `resize` writes each element; `vec![0; len]` would not touch fresh pages (calloc).
    v.resize(len, T::default());
    v.clear();
    v
}

impl TopologySpare {
    /// Spare buffers for updates of `topology` that grow it by up to the fraction `headroom`,
    /// their memory written now.
    pub fn for_topology(topology: &Topology, headroom: f64) -> Self {
        let grow = |len: usize| len + (len as f64 * headroom).ceil() as usize;
        let edges = grow(topology.edges.len());
        let vertices = grow(topology.vertex_face_offsets.len());
        Self {
            edges: touched(edges),
            edge_faces: touched(edges),
            edge_face_count: touched(edges),
            vertex_face_offsets: touched(vertices),
            vertex_faces: touched(grow(topology.vertex_faces.len())),
            index: touched(edges),
            parent: touched(vertices),
            label: touched(vertices),
            marks: vec![false; vertices],
        }
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        (self.edges.capacity() + self.edge_faces.capacity()) * 8
            + (self.edge_face_count.capacity()
                + self.vertex_face_offsets.capacity()
                + self.vertex_faces.capacity()
                + self.index.capacity()
                + self.parent.capacity()
                + self.label.capacity())
                * 4
            + self.marks.capacity()
    }
}

impl Topology {
    /// Room for the arrays an update rebuilds to grow by the fraction `headroom` without
    /// moving (see [`TopologySpare`]).
    pub fn reserve_headroom(&mut self, headroom: f64) {
        let more = |len: usize| (len as f64 * headroom).ceil() as usize;
        self.edges.reserve(more(self.edges.len()));
        self.edge_faces.reserve(more(self.edge_faces.len()));
        self.edge_face_count.reserve(more(self.edge_face_count.len()));
        self.vertex_face_offsets.reserve(more(self.vertex_face_offsets.len()));
        self.vertex_faces.reserve(more(self.vertex_faces.len()));
        self.face_edges.reserve(more(self.face_edges.len()));
        self.face_components.reserve(more(self.face_components.len()));
    }

    /// Updates the topology of `old_triangles` (which it describes) to `triangles`: the same
    /// faces, some with other corners, possibly more faces appended, over `vertex_count`
    /// vertices (no fewer than before). The result is identical to `Topology::build(triangles,
    /// vertex_count)`; the work grows with the number of changed faces, apart from a few linear
    /// passes (renumbering the face edges, the boundary loops and the components).
    pub fn update(&mut self, old_triangles: &[[u32; 3]], triangles: &[[u32; 3]], vertex_count: usize) {
        self.update_with(old_triangles, triangles, vertex_count, &mut TopologySpare::default(), None);
    }

    /// [`Topology::update`] building into the buffers of `spare`, which gets the topology's old
    /// ones back. With a `pool` (the caller runs inside it) the components (a pass over every
    /// face, 0.4 ms of the 1.1 ms of an update on the issue-5 balloon's first crack) are found
    /// on another thread while this one updates the edges and fans: they need only the faces.
    pub fn update_with(
        &mut self,
        old_triangles: &[[u32; 3]],
        triangles: &[[u32; 3]],
        vertex_count: usize,
        spare: &mut TopologySpare,
        pool: Option<&WorkerPool>,
    ) {
        let old_vertex_count = self.vertex_face_offsets.len().saturating_sub(1);
        // (A face index must fit in 31 bits for the packed sort of `update_vertex_faces`.)
        if triangles.len() < old_triangles.len()
            || triangles.len() >= 1 << 31
            || self.face_edges.len() != old_triangles.len()
            || self.vertex_face_offsets.is_empty()
            || vertex_count < old_vertex_count
        {
            *self = Topology::build(triangles, vertex_count);
            return;
        }
        let mut face_components = std::mem::take(&mut self.face_components);
        let (mut parent, mut label) = (std::mem::take(&mut spare.parent), std::mem::take(&mut spare.label));
        let mut components = || components_into(triangles, vertex_count, &mut parent, &mut label, &mut face_components);
        let count = match pool {
            Some(pool) => {
                pool.join(
                    || self.update_edges_and_fans(old_triangles, triangles, vertex_count, spare, Some(pool)),
                    components,
                )
                .1
            }
            None => {
                self.update_edges_and_fans(old_triangles, triangles, vertex_count, spare, None);
                components()
            }
        };
        self.face_components = face_components;
        self.component_count = count;
        (spare.parent, spare.label) = (parent, label);
    }

    /// Everything of [`Topology::update_with`] but the components; with a `pool` (the caller
    /// runs inside it) the fans and the boundary loops at the same time.
    fn update_edges_and_fans(
        &mut self,
        old_triangles: &[[u32; 3]],
        triangles: &[[u32; 3]],
        vertex_count: usize,
        spare: &mut TopologySpare,
        pool: Option<&WorkerPool>,
    ) {
        let old_face_count = old_triangles.len();
        let changed: Vec<u32> = (0..triangles.len())
            .filter(|&f| f >= old_face_count || old_triangles[f] != triangles[f])
            .map(|f| f as u32)
            .collect();
        let old_corners = |f: u32| (f as usize) < old_face_count;
        let touched = self.update_vertex_faces(old_triangles, triangles, vertex_count, &changed, spare);

        // Edges whose faces may have changed: every side of a changed face, before and after.
        // Sorted as `min << 32 | max` (the same order as the pairs; sorting the pairs took
        // 0.7 ms of a 3.4 ms update in the issue-5 balloon's fracture storm, some 13k sides).
        let mut packed: Vec<u64> = Vec::new();
        let pack = |[a, b]: [u32; 2]| (a as u64) << 32 | b as u64;
        for &f in &changed {
            if old_corners(f) {
                packed.extend(sides(old_triangles[f as usize]).map(pack));
            }
            packed.extend(sides(triangles[f as usize]).map(pack));
        }
        packed.sort_unstable();
        packed.dedup();
        let keys: Vec<[u32; 2]> = packed.iter().map(|&k| [(k >> 32) as u32, k as u32]).collect();
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
        // Whether the loops before the update were cycles each started at its smallest vertex
        // (see `updated_boundary_loops`): one fan at every vertex and a consistent winding.
        let old_loops_are_cycles = self.inconsistent_edges.is_empty() && self.non_manifold_vertices.is_empty();
        let capacity = old_edge_count + groups.len();
        let mut index = std::mem::take(&mut spare.index);
        index.clear();
        index.resize(old_edge_count, u32::MAX);
        let mut edges = std::mem::take(&mut spare.edges);
        let mut edge_faces = std::mem::take(&mut spare.edge_faces);
        let mut edge_face_count = std::mem::take(&mut spare.edge_face_count);
        edges.clear();
        edge_faces.clear();
        edge_face_count.clear();
        edges.reserve(capacity);
        edge_faces.reserve(capacity);
        edge_face_count.reserve(capacity);
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
        spare.edges = std::mem::replace(&mut self.edges, edges);
        spare.edge_faces = std::mem::replace(&mut self.edge_faces, edge_faces);
        spare.edge_face_count = std::mem::replace(&mut self.edge_face_count, edge_face_count);
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
        spare.index = index;

        // Fans change only at the ends of the regrouped edges and where the faces changed.
        let mut again: Vec<u32> = keys.iter().flatten().copied().chain(touched).collect();
        again.sort_unstable();
        again.dedup();
        // The fans and the boundary loops (each a pass of 0.5-0.9 ms in the storm above) read
        // what is done by now: at the same time with a `pool`.
        let old_loops = std::mem::take(&mut self.boundary_loops);
        let fans = || {
            let mut non_manifold: Vec<u32> = self
                .non_manifold_vertices
                .iter()
                .copied()
                .filter(|v| again.binary_search(v).is_err())
                .chain(again.iter().copied().filter(|&v| self.fan_count(triangles, v) > 1))
                .collect();
            non_manifold.sort_unstable();
            non_manifold
        };
        let marks = &mut spare.marks;
        // (Not even tried where the old loops were no cycles.)
        let loops =
            || old_loops_are_cycles.then(|| self.updated_boundary_loops(triangles, &again, old_loops, marks)).flatten();
        let (non_manifold, loops) = match pool {
            Some(pool) => pool.join(fans, loops),
            None => (fans(), loops()),
        };
        // The loops found from the old ones hold only where every vertex has one fan, before
        // and after (see `updated_boundary_loops`); else all of them are found again.
        self.boundary_loops = match loops {
            Some(loops) if non_manifold.is_empty() => loops,
            _ => self.boundary_loops_of(triangles),
        };
        self.non_manifold_vertices = non_manifold;
    }

    /// The boundary loops after an update, from the loops before it (`old_loops`): those that
    /// pass through none of the vertices `again` (sorted; every vertex whose faces or edges
    /// changed) are kept as they are, and the loops through those vertices are walked anew.
    /// None where that would not give the loops of a new build ([`Topology::boundary_loops_of`]),
    /// which the caller then makes.
    ///
    /// Why: that build is a walk over every boundary half-edge of the mesh, reading scattered
    /// faces; after the issue-5 balloon has burst (15,000 pieces, 50,000 vertices, each step
    /// still cracking some 60 springs) it took about 3 ms of every step, a third of the fracture
    /// phase, for loops of which a few hundred changed.
    ///
    /// When it holds: with every vertex in a single fan ([`Topology::non_manifold_vertices`]
    /// empty) and the winding consistent (no [`Topology::inconsistent_edges`]), a vertex's faces
    /// form one chain or ring through manifold edges, consistently wound, so at most one
    /// boundary half-edge leaves it and at most one arrives. The boundary half-edges then form
    /// disjoint cycles, and the build's walk, which starts each loop at the smallest half-edge
    /// not yet used, starts each cycle at its smallest vertex and lists the cycles in the order
    /// of those vertices. That must hold after the update (the caller checks the fans, this
    /// the winding) and before it (the caller checks both): a loop through no vertex of `again`
    /// has the same half-edges as before, so it is a cycle now, but only a mesh that was as
    /// clean before had listed it whole (one with a face wound against its neighbours lists
    /// pieces of loops, and an update that turns the face back leaves pieces that no changed
    /// vertex touches: found by review). Each walk here also checks that every vertex it passes
    /// has exactly one boundary half-edge leaving it and one arriving.
    fn updated_boundary_loops(
        &self,
        triangles: &[[u32; 3]],
        again: &[u32],
        old_loops: Vec<Vec<u32>>,
        marks: &mut Vec<bool>,
    ) -> Option<Vec<Vec<u32>>> {
        if !self.inconsistent_edges.is_empty() {
            return None;
        }
        let vertex_count = self.vertex_face_offsets.len() - 1;
        // `marks` is all false between updates: set for `again` here, cleared again below.
        if marks.len() < vertex_count {
            marks.resize(vertex_count, false);
        }
        for &v in again {
            marks[v as usize] = true;
        }
        let mut loops: Vec<Vec<u32>> =
            old_loops.into_iter().filter(|ring| !ring.iter().any(|&v| marks[v as usize])).collect();
        let kept = loops.len();
        // The boundary half-edges at `v`: how many leave and arrive, and where the last one
        // leaving leads.
        let boundary_at = |v: u32| {
            let (mut leaving, mut arriving, mut next) = (0, 0, v);
            for &f in self.faces_of_vertex(v) {
                let t = triangles[f as usize];
                for side in 0..3 {
                    let e = self.face_edges[f as usize][side];
                    if e == u32::MAX || self.edge_face_count[e as usize] != 1 {
                        continue;
                    }
                    if t[side] == v {
                        leaving += 1;
                        next = t[(side + 1) % 3];
                    } else if t[(side + 1) % 3] == v {
                        arriving += 1;
                    }
                }
            }
            (leaving, arriving, next)
        };
        let mut consistent = true;
        'walks: for &start in again {
            if !marks[start as usize] {
                continue; // on a loop walked already
            }
            marks[start as usize] = false;
            if let (0, 0, _) = boundary_at(start) {
                continue; // not on the boundary (the walk checks the rest)
            }
            let mut ring = vec![start];
            let mut v = start;
            loop {
                let (1, 1, next) = boundary_at(v) else {
                    consistent = false;
                    break 'walks;
                };
                if next == start {
                    break;
                }
                // A longer walk has passed a vertex twice: not a cycle through `start`.
                if ring.len() > vertex_count {
                    consistent = false;
                    break 'walks;
                }
                marks[next as usize] = false;
                ring.push(next);
                v = next;
            }
            // Started at its smallest vertex, as the build's walk starts it.
            let smallest = (0..ring.len()).min_by_key(|&k| ring[k]).unwrap_or(0);
            ring.rotate_left(smallest);
            loops.push(ring);
        }
        for &v in again {
            marks[v as usize] = false;
        }
        if !consistent {
            return None;
        }
        // The kept loops are in order of their first vertex, so are the new ones once sorted:
        // merged.
        loops[kept..].sort_unstable_by_key(|ring| ring[0]);
        let mut merged = Vec::with_capacity(loops.len());
        let mut new = loops.split_off(kept).into_iter().peekable();
        for ring in loops {
            while let Some(first) = new.next_if(|n| n[0] < ring[0]) {
                merged.push(first);
            }
            merged.push(ring);
        }
        merged.extend(new);
        Some(merged)
    }

    /// Updates the faces around each vertex for the faces `changed`; returns the vertices whose
    /// faces changed.
    fn update_vertex_faces(
        &mut self,
        old_triangles: &[[u32; 3]],
        triangles: &[[u32; 3]],
        vertex_count: usize,
        changed: &[u32],
        spare: &mut TopologySpare,
    ) -> Vec<u32> {
        // (vertex, face, added): faces that left or joined a vertex, sorted (as
        // `vertex << 32 | face << 1 | added`, faster to sort than the tuples; a face index
        // takes 31 bits, see `Topology::update_with`).
        let mut packed: Vec<u64> = Vec::new();
        let pack = |v: u32, f: u32, added: bool| (v as u64) << 32 | (f as u64) << 1 | added as u64;
        for &f in changed {
            let new = triangles[f as usize];
            let old = old_triangles.get(f as usize).copied();
            if let Some(old) = old {
                packed.extend(distinct(old).filter(|v| !new.contains(v)).map(|v| pack(v, f, false)));
            }
            packed.extend(distinct(new).filter(|v| old.is_none_or(|old| !old.contains(v))).map(|v| pack(v, f, true)));
        }
        packed.sort_unstable();
        let moves: Vec<(u32, u32, bool)> =
            packed.iter().map(|&m| ((m >> 32) as u32, (m as u32) >> 1, m & 1 == 1)).collect();
        let old_vertex_count = self.vertex_face_offsets.len() - 1;
        let (old_offsets, old_faces) = (&self.vertex_face_offsets, &self.vertex_faces);
        let added = moves.iter().filter(|m| m.2).count();
        let mut offsets = std::mem::take(&mut spare.vertex_face_offsets);
        let mut faces = std::mem::take(&mut spare.vertex_faces);
        offsets.clear();
        faces.clear();
        offsets.reserve(vertex_count + 1);
        faces.reserve(old_faces.len() + added);
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
        spare.vertex_face_offsets = std::mem::replace(&mut self.vertex_face_offsets, offsets);
        spare.vertex_faces = std::mem::replace(&mut self.vertex_faces, faces);
        touched
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Topology, torus_grid};
    use super::{TopologySpare, search_from};

    /// An update within the headroom builds into the spare's buffers and hands the topology's
    /// old ones back: no array is allocated (or moved), so a cracking step makes no page faults
    /// there. Two updates in a row: the second reuses the first's old buffers.
    #[test]
    fn updates_within_the_headroom_reuse_the_spare_buffers() {
        let triangles = torus_grid(12, 10);
        let vertices = 120;
        let mut topology = Topology::build(&triangles, vertices);
        topology.reserve_headroom(0.125);
        let mut spare = TopologySpare::for_topology(&topology, 0.125);
        let mut current = triangles.clone();
        for round in 0..2u32 {
            let held = [spare.edges.as_ptr() as usize, spare.vertex_faces.as_ptr() as usize];
            let own = [topology.edges.as_ptr() as usize, topology.vertex_faces.as_ptr() as usize];
            // Split one vertex's fan: face 0's corner 0 gets a new vertex.
            let old = current.clone();
            current[round as usize][0] = (vertices as u32) + round;
            topology.update_with(&old, &current, vertices + 1 + round as usize, &mut spare, None);
            assert_eq!(topology, Topology::build(&current, vertices + 1 + round as usize), "round {round}");
            assert_eq!([topology.edges.as_ptr() as usize, topology.vertex_faces.as_ptr() as usize], held);
            assert_eq!([spare.edges.as_ptr() as usize, spare.vertex_faces.as_ptr() as usize], own);
        }
    }

    /// Splits every vertex with several fans into one vertex per fan (the first fan keeps it),
    /// as a crack does: the result has one fan at every vertex. Returns the vertex count.
    fn split_pinches(triangles: &mut [[u32; 3]], mut vertices: u32) -> u32 {
        let topology = Topology::build(triangles, vertices as usize);
        for &v in &topology.non_manifold_vertices {
            let faces = topology.faces_of_vertex(v).to_vec();
            // Fans: faces joined through the manifold edges at v (a union-find on their places).
            let mut fan: Vec<usize> = (0..faces.len()).collect();
            let root = |fan: &mut Vec<usize>, mut i: usize| {
                while fan[i] != i {
                    i = fan[i];
                }
                i
            };
            for (i, &f) in faces.iter().enumerate() {
                for side in 0..3 {
                    let t = triangles[f as usize];
                    let e = topology.face_edges[f as usize][side];
                    if (t[side] != v && t[(side + 1) % 3] != v)
                        || e == u32::MAX
                        || topology.edge_face_count[e as usize] != 2
                    {
                        continue;
                    }
                    // (A degenerate face can run along an edge twice: no other face.)
                    let Some(other) = topology.edge_faces[e as usize].into_iter().find(|&g| g != f) else {
                        continue;
                    };
                    let j = faces.iter().position(|&g| g == other).unwrap();
                    let (a, b) = (root(&mut fan, i), root(&mut fan, j));
                    fan[a.max(b)] = a.min(b);
                }
            }
            let mut copies = std::collections::BTreeMap::new();
            for (i, &f) in faces.iter().enumerate() {
                let r = root(&mut fan, i);
                if r == 0 {
                    continue;
                }
                let copy = *copies.entry(r).or_insert_with(|| {
                    vertices += 1;
                    vertices - 1
                });
                triangles[f as usize].iter_mut().filter(|c| **c == v).for_each(|c| *c = copy);
            }
        }
        vertices
    }

    /// Cracks on a closed oriented surface (faces cut free from their neighbours, then every
    /// pinched vertex split into its fans, as the fracture leaves a surface: one fan at every
    /// vertex): the boundary loops found from the old ones are those of a new build in every
    /// round that starts and ends that clean, and the whole update equals a new build in every
    /// round (with and without a pool). Some rounds leave a pinch or turn a face against its
    /// neighbours, in the middle of a run: the rounds after them start from an unclean mesh.
    #[test]
    fn boundary_loops_from_the_old_ones_are_those_of_a_new_build() {
        use super::super::tests_rng::Rng;
        let mut rng = Rng(4242);
        let (mut from_the_old_ones, mut unclean_starts) = (0, 0);
        for case in 0..40u32 {
            let mut triangles = torus_grid(9 + case % 4, 7 + case % 3);
            let mut vertices = (9 + case % 4) * (7 + case % 3);
            let mut topology = Topology::build(&triangles, vertices as usize);
            let pool = (case % 2 == 0).then(|| crate::parallel::WorkerPool::new(2).unwrap());
            let mut spare = TopologySpare::for_topology(&topology, 0.1);
            for round in 0..8 {
                let old = triangles.clone();
                for _ in 0..1 + rng.below(3) {
                    let f = rng.below(triangles.len() as u32) as usize;
                    triangles[f] = [vertices, vertices + 1, vertices + 2];
                    vertices += 3;
                }
                // Rounds 3 and 4 of every fourth case: a pinch left (and one made: a corner
                // of one face welded to a vertex of another); of the next ones a face turned
                // over in round 3 and back in round 5.
                let pinch_left = case % 4 == 0 && (round == 3 || round == 4);
                if pinch_left {
                    let (f, g) = (rng.below(old.len() as u32) as usize, rng.below(old.len() as u32) as usize);
                    triangles[f][0] = triangles[g][0];
                } else {
                    vertices = split_pinches(&mut triangles, vertices);
                }
                if case % 4 == 1 && (round == 3 || round == 5) {
                    triangles[0].swap(1, 2);
                }
                let built = Topology::build(&triangles, vertices as usize);
                let what = format!("case {case}, round {round}");
                let clean = |t: &Topology| t.non_manifold_vertices.is_empty() && t.inconsistent_edges.is_empty();
                unclean_starts += !clean(&topology) as usize;
                if clean(&topology) && clean(&built) {
                    // Every corner of a changed face, before and after: what the update walks.
                    let mut again: Vec<u32> = (0..old.len())
                        .filter(|&f| old[f] != triangles[f])
                        .flat_map(|f| old[f].into_iter().chain(triangles[f]))
                        .collect();
                    again.sort_unstable();
                    again.dedup();
                    let mut marks = Vec::new();
                    let loops =
                        built.updated_boundary_loops(&triangles, &again, topology.boundary_loops.clone(), &mut marks);
                    assert_eq!(loops.as_ref(), Some(&built.boundary_loops), "{what}: loops from the old ones");
                    assert!(marks.iter().all(|m| !m), "{what}: the marks are cleared");
                    from_the_old_ones += 1;
                }
                topology.update_with(&old, &triangles, vertices as usize, &mut spare, pool.as_ref());
                assert_eq!(topology, built, "{what}: the update");
                assert!(!built.boundary_loops.is_empty());
            }
        }
        assert!(
            from_the_old_ones > 200 && unclean_starts > 20,
            "{from_the_old_ones} clean rounds, {unclean_starts} from unclean"
        );
    }

    /// An open grid with one face wound against its neighbours lists pieces of its boundary
    /// loops, not loops; an update that turns the face back gives the loops of a new build
    /// (found by review: the pieces that no changed vertex touched were kept as loops).
    #[test]
    fn turning_a_face_back_gives_the_loops_of_a_new_build() {
        for (nu, nv) in [(1, 2), (1, 3), (2, 2), (3, 4), (4, 4)] {
            let grid = open_grid(nu, nv, 0);
            let n = ((nu + 1) * (nv + 1)) as usize;
            for f in 0..grid.len() {
                let mut turned = grid.clone();
                turned[f].swap(1, 2);
                let mut topology = Topology::build(&turned, n);
                topology.update(&turned, &grid, n);
                assert_eq!(topology, Topology::build(&grid, n), "{nu}x{nv} grid, face {f} turned back");
            }
        }
    }

    /// A grid of `nu` by `nv` squares (two faces each), open, its vertices numbered from `base`.
    fn open_grid(nu: u32, nv: u32, base: u32) -> Vec<[u32; 3]> {
        let id = |i: u32, j: u32| base + i * (nv + 1) + j;
        let mut t = Vec::new();
        for i in 0..nu {
            for j in 0..nv {
                t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        t
    }

    /// Updates of every kind (from a review that found the bug above with it), each compared
    /// with a new build: faces cut free or given a new corner, turned round, turned over, made
    /// degenerate, set back to an earlier round's corners, appended (alone, on a boundary edge,
    /// closing a three-vertex hole), boundary vertices welded, a whole piece turned over, unused
    /// vertices added, random corners; after most rounds the pinches split (the fracture's
    /// clean surfaces), after the others left. Closed and open surfaces, separate triangles, a
    /// fan with a tetrahedron; with and without spare buffers and a pool.
    #[test]
    fn updates_of_every_kind_give_the_same_as_a_new_build() {
        use super::super::tests_rng::Rng;
        let mut rng = Rng(0x5eed_1234_abcd);
        for case in 0..1500u32 {
            let (mut triangles, mut vertices) = match case % 5 {
                0 => (torus_grid(6 + case % 5, 5 + case % 4), (6 + case % 5) * (5 + case % 4)),
                1 => (open_grid(3 + case % 4, 3 + case % 3, 0), (4 + case % 4) * (4 + case % 3)),
                2 => ((0..6).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect(), 18 + case % 3),
                3 => {
                    let mut t = torus_grid(5, 4);
                    t.extend(open_grid(2, 3, 20));
                    t.push([32, 33, 34]);
                    (t, 37)
                }
                _ => {
                    // An open fan around vertex 0 and a closed tetrahedron.
                    let mut t: Vec<[u32; 3]> = (0..5).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
                    t.extend([[7, 9, 8], [7, 8, 10], [8, 9, 10], [7, 10, 9]]);
                    (t, 11 + case % 2)
                }
            };
            if rng.below(2) == 0 {
                vertices = split_pinches(&mut triangles, vertices);
            }
            let mut topology = Topology::build(&triangles, vertices as usize);
            let pool = (case % 3 == 0).then(|| crate::parallel::WorkerPool::new(2).unwrap());
            let mut spare = (case % 4 != 1).then(|| TopologySpare::for_topology(&topology, 0.05 * (case % 3) as f64));
            let mut history = vec![triangles.clone()];
            for round in 0..10 {
                let old = triangles.clone();
                let face_count = triangles.len() as u32;
                for _ in 0..1 + rng.below(3) {
                    let f = rng.below(face_count.max(1)) as usize;
                    let loops = &topology.boundary_loops;
                    match rng.below(16) {
                        0 | 1 => {
                            triangles[f] = [vertices, vertices + 1, vertices + 2];
                            vertices += 3;
                        }
                        2 | 3 => {
                            triangles[f][rng.below(3) as usize] = vertices;
                            vertices += 1;
                        }
                        4 => triangles[f].rotate_left(1 + rng.below(2) as usize),
                        5 => triangles[f].swap(1, 2),
                        6 => {
                            triangles[f] = [vertices; 3];
                            vertices += 1;
                        }
                        7 => triangles[f] = [triangles[f][0], triangles[f][0], triangles[f][1]],
                        8 => {
                            let earlier = &history[rng.below(history.len() as u32) as usize];
                            for g in 0..earlier.len().min(triangles.len()) {
                                if rng.below(2) == 0 {
                                    triangles[g] = earlier[g];
                                }
                            }
                        }
                        9 => {
                            triangles.push([vertices, vertices + 1, vertices + 2]);
                            vertices += 3;
                        }
                        10 | 11 if !loops.is_empty() => {
                            let l = &loops[rng.below(loops.len() as u32) as usize];
                            let k = rng.below(l.len() as u32) as usize;
                            let (a, b) = (l[k], l[(k + 1) % l.len()]);
                            if l.len() == 3 && rng.below(2) == 0 {
                                triangles.push([l[2], l[1], l[0]]);
                            } else if rng.below(2) == 0 {
                                triangles.push([b, a, vertices]);
                                vertices += 1;
                            } else if l.len() >= 3 {
                                triangles.push([l[(k + 2) % l.len()], b, a]);
                            }
                        }
                        12 if !loops.is_empty() => {
                            let (l, m) = (
                                &loops[rng.below(loops.len() as u32) as usize],
                                &loops[rng.below(loops.len() as u32) as usize],
                            );
                            let (u, w) = (l[rng.below(l.len() as u32) as usize], m[rng.below(m.len() as u32) as usize]);
                            triangles.iter_mut().flatten().filter(|c| **c == u).for_each(|c| *c = w);
                        }
                        13 => {
                            let piece = topology.face_components.get(f).copied();
                            for g in 0..topology.face_components.len().min(triangles.len()) {
                                if Some(topology.face_components[g]) == piece {
                                    triangles[g].swap(1, 2);
                                }
                            }
                        }
                        14 => vertices += rng.below(3),
                        _ => triangles[f][rng.below(3) as usize] = rng.below(vertices),
                    }
                }
                if rng.below(10) < 7 {
                    vertices = split_pinches(&mut triangles, vertices);
                }
                match spare.as_mut() {
                    Some(spare) => {
                        topology.update_with(&old, &triangles, vertices as usize, spare, pool.as_ref());
                        assert!(spare.marks.iter().all(|m| !m), "case {case}, round {round}: marks left set");
                    }
                    None => topology.update(&old, &triangles, vertices as usize),
                }
                assert_eq!(topology, Topology::build(&triangles, vertices as usize), "case {case}, round {round}");
                history.push(triangles.clone());
            }
        }
    }

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
