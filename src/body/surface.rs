//! The body's changing surface: vertex state (structure of arrays), the fracture bookkeeping,
//! and rebuilding springs and fragments from the triangles after a topology change.

use glam::Vec3;

use super::headroom::reserve_for;
use super::springs::{Adjacency, Springs};
use crate::mesh::{Topology, TopologySpare};

/// Per-vertex state, structure of arrays.
#[derive(Clone, Debug, Default)]
pub(crate) struct Nodes {
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub mass: Vec<f32>,
    /// 0 for pinned vertices (and vertices without mass).
    pub inv_mass: Vec<f32>,
    /// Rest positions (the input mesh's; copies share their origin's): the rest shape from which
    /// every spring's rest length comes, also for springs made by a topology change.
    pub rest: Vec<Vec3>,
}

impl Nodes {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Room for `more` vertices in every array (appended by fracture without moving them).
    pub fn reserve(&mut self, more: usize) {
        self.x.reserve(more);
        self.v.reserve(more);
        self.mass.reserve(more);
        self.inv_mass.reserve(more);
        self.rest.reserve(more);
    }

    pub fn is_pinned(&self, i: usize) -> bool {
        self.inv_mass[i] == 0.0
    }

    /// Sets the mass of vertex i, keeping it pinned if it was.
    pub fn set_mass(&mut self, i: usize, mass: f32) {
        let pinned = self.is_pinned(i);
        self.mass[i] = mass;
        self.inv_mass[i] = if pinned || mass <= 0.0 { 0.0 } else { 1.0 / mass };
    }

    pub fn memory_bytes(&self) -> usize {
        (self.x.capacity() + self.v.capacity() + self.rest.capacity()) * 12
            + (self.mass.capacity() + self.inv_mass.capacity()) * 4
    }
}

/// Fracture bookkeeping (allocated only when the body can break).
#[derive(Debug, Default)]
pub(crate) struct Fracture {
    /// Per face, bit k set when side k (corner k to corner k+1) is a broken edge: no spring while
    /// the edge still joins two faces, a spring at [`Fracture::opened_rest`] once the crack has
    /// parted them ([`edge_is_broken`]).
    pub broken: Vec<u8>,
    /// Per vertex, the input-mesh vertex it was split from.
    pub origin: Vec<u32>,
    /// The buffers a topology change builds the next topology in (see [`TopologySpare`]) and
    /// the triangles before the change: kept, so that a cracking step allocates no large array
    /// (whose first-touch page faults cost more than the work).
    pub spare: TopologySpare,
    pub before: Vec<[u32; 3]>,
    /// Per vertex (as far as it is long), true for the vertices of a released core block and
    /// the centre of the patch it left: they release no block themselves (see
    /// `core_block::release`).
    pub in_core: Vec<bool>,
    /// The rest length of each side of an opened crack, by face and side (`3 face + side`:
    /// faces keep their index through every split, where a side's vertices may be renamed),
    /// sorted by that key, set when the crack opened there ([`opened_side_rest`]). A vector,
    /// not a map, so that its memory is known to the byte.
    pub opened_rest: Vec<(u32, f32)>,
    /// The broken sides (`3 face + side`) that may still join two faces, or have opened and
    /// not yet been given a rest length: what [`Fracture::record_opened_sides`] and the springs'
    /// rebuild read instead of every face's bits. A side leaves once its crack has opened and
    /// it is recorded (no change joins a side of one face to another face again: a split only
    /// parts faces, and a core block's caps take new faces). After the issue-5 balloon's burst
    /// some 30,000 sides are broken and a few hundred change a step: scanning them all took
    /// 0.8 ms of each step's 5 ms fracture phase. Unsorted between [`Fracture::mark`] and the
    /// next record.
    pub pending: Vec<u32>,
    /// Per vertex, whether the last topology change changed its fan (a face around it, before
    /// or after, changed its corners; a vertex it appended): what the gas's rings are made
    /// again for ([`Fracture::mark_changed`]).
    pub changed: Vec<bool>,
}

impl Fracture {
    pub fn new(vertex_count: usize, face_count: usize) -> Self {
        Self {
            broken: vec![0; face_count],
            origin: (0..vertex_count as u32).collect(),
            spare: TopologySpare::default(),
            before: Vec::new(),
            in_core: Vec::new(),
            opened_rest: Vec::new(),
            changed: Vec::new(),
            pending: Vec::new(),
        }
    }

    /// Whether [`Fracture::pending`] holds every broken side that the full scans of old read
    /// (every face's bits): each one that still joins two faces (or has no edge), and each one
    /// that has opened without a recorded rest length.
    #[cfg(test)]
    pub fn pending_is_complete(&self, topology: &Topology) -> bool {
        (0..self.broken.len()).all(|f| {
            (0..3).filter(|&side| self.is_broken(f as u32, side)).all(|side| {
                let key = 3 * f as u32 + side as u32;
                let e = topology.face_edges[f][side];
                let done = e != u32::MAX
                    && topology.edge_face_count[e as usize] == 1
                    && self.opened_side(f as u32, side).is_some();
                done || self.pending.contains(&key)
            })
        })
    }

    /// Marks side `side` of face `face` broken.
    pub fn mark(&mut self, face: u32, side: usize) {
        self.broken[face as usize] |= 1 << side;
        self.pending.push(3 * face + side as u32);
    }

    /// Records the rest length of every side of an opened crack in `topology` (that of the
    /// current triangles) that has none yet: [`opened_side_rest`] of its length at positions
    /// `x` and its rest length from `rest`. A side keeps what it was given when its crack opened,
    /// through later splits of its ends (as the crack runs on) and core blocks.
    pub fn record_opened_sides(&mut self, topology: &Topology, x: &[Vec3], rest: &[Vec3]) {
        // The sides are visited in key order, as the known ones are kept: a cursor walks those
        // alongside, and the new ones (in key order too) are merged in at the end, in place. (A search
        // in the known sides for each, and a sort of all of them after, took 0.26-0.66 ms of
        // each step of the issue-5 balloon's fracture storm, thousands of sides.)
        // Only the pending sides can be new ones (see `Fracture::pending`); those that opened
        // leave the list, recorded now or known already.
        let mut new = Vec::new();
        let mut known = self.opened_rest.iter().map(|&(k, _)| k).peekable();
        let mut pending = std::mem::take(&mut self.pending);
        pending.sort_unstable();
        pending.dedup();
        pending.retain(|&key| {
            let (f, side) = ((key / 3) as usize, (key % 3) as usize);
            if self.broken[f] & (1 << side) == 0 {
                return false;
            }
            let e = topology.face_edges[f][side];
            while known.next_if(|&k| k < key).is_some() {}
            if e == u32::MAX || topology.edge_face_count[e as usize] != 1 {
                return true;
            }
            if known.peek() != Some(&key) {
                let [a, b] = topology.edges[e as usize].map(|v| v as usize);
                new.push((key, opened_side_rest((x[b] - x[a]).length(), (rest[b] - rest[a]).length())));
            }
            false
        });
        self.pending = pending;
        // Merged in place from the back (the new keys are none of the known ones).
        let known = self.opened_rest.len();
        self.opened_rest.resize(known + new.len(), (0, 0.0));
        let (mut i, mut j) = (known, new.len());
        for k in (0..known + new.len()).rev() {
            if j == 0 {
                break;
            }
            if i > 0 && self.opened_rest[i - 1].0 > new[j - 1].0 {
                self.opened_rest[k] = self.opened_rest[i - 1];
                i -= 1;
            } else {
                self.opened_rest[k] = new[j - 1];
                j -= 1;
            }
        }
    }

    /// The rest length recorded for side `side` of face `face`, if its crack has opened.
    pub fn opened_side(&self, face: u32, side: usize) -> Option<f32> {
        let key = 3 * face + side as u32;
        self.opened_rest.binary_search_by_key(&key, |&(k, _)| k).ok().map(|i| self.opened_rest[i].1)
    }

    /// Gives side `side` of face `face` the rest length `length` (a core block's cap taking the
    /// place of a crack's side).
    pub fn set_opened_side(&mut self, face: u32, side: usize, length: f32) {
        let key = 3 * face + side as u32;
        match self.opened_rest.binary_search_by_key(&key, |&(k, _)| k) {
            Ok(i) => self.opened_rest[i].1 = length,
            Err(i) => self.opened_rest.insert(i, (key, length)),
        }
    }

    /// True when vertex `i` belongs to a released core block or is the centre of a patch one
    /// left.
    pub fn is_in_core(&self, i: usize) -> bool {
        self.in_core.get(i).copied().unwrap_or(false)
    }

    /// Marks vertex `i` as [`Fracture::is_in_core`].
    pub fn mark_in_core(&mut self, i: usize) {
        if self.in_core.len() <= i {
            self.in_core.resize(i + 1, false);
        }
        self.in_core[i] = true;
    }

    /// [`Fracture::new`] for a body of `topology` that will crack: its spare buffers made
    /// (their memory written) now, with room for the topology to grow by the fraction
    /// `headroom`, and room for as many more vertices.
    pub fn ready_to_crack(topology: &Topology, face_count: usize, headroom: f64) -> Self {
        let vertex_count = topology.vertex_face_offsets.len().saturating_sub(1);
        let mut fracture = Self::new(vertex_count, face_count);
        let more = |len: usize| (len as f64 * headroom).ceil() as usize;
        fracture.origin.reserve(more(vertex_count));
        fracture.broken.reserve(more(face_count));
        fracture.spare = TopologySpare::for_topology(topology, headroom);
        fracture.before = vec![[u32::MAX; 3]; face_count + more(face_count)];
        fracture.before.clear();
        reserve_for(&mut fracture.changed, vertex_count, headroom);
        fracture
    }

    /// Starts the marks of a topology change: no vertex of the `vertex_count` changed yet.
    pub fn start_marks(&mut self, vertex_count: usize) {
        self.changed.clear();
        self.changed.resize(vertex_count, false);
    }

    /// Marks in [`Fracture::changed`] (sized for `vertex_count` vertices, the new ones marked)
    /// the vertices of every face that differs between `before` and `triangles` (faces keep
    /// their index; new ones are appended), on both versions of the face.
    pub fn mark_changed(&mut self, before: &[[u32; 3]], triangles: &[[u32; 3]], vertex_count: usize) {
        self.changed.resize(vertex_count, true);
        for (f, t) in triangles.iter().enumerate() {
            let old = before.get(f);
            if old != Some(t) {
                for &v in t.iter().chain(old.into_iter().flatten()) {
                    self.changed[v as usize] = true;
                }
            }
        }
    }

    pub fn memory_bytes(&self) -> usize {
        self.broken.capacity()
            + self.origin.capacity() * 4
            + self.spare.memory_bytes()
            + self.before.capacity() * 12
            + self.in_core.capacity()
            + self.opened_rest.capacity() * std::mem::size_of::<(u32, f32)>()
            + self.pending.capacity() * 4
            + self.changed.capacity()
    }

    /// Appends a vertex at `x` with velocity `v` and `mass`, split from `from` (pinned if `from`
    /// is) with rest position `rest`; returns its index.
    pub fn add_vertex(&mut self, nodes: &mut Nodes, from: usize, x: Vec3, v: Vec3, mass: f32, rest: Vec3) -> u32 {
        let index = nodes.len() as u32;
        let pinned = nodes.is_pinned(from) && nodes.mass[from] > 0.0;
        nodes.x.push(x);
        nodes.v.push(v);
        nodes.mass.push(mass);
        nodes.inv_mass.push(if pinned || mass <= 0.0 { 0.0 } else { 1.0 / mass });
        nodes.rest.push(rest);
        self.origin.push(self.origin[from]);
        index
    }

    /// True when side `side` of `face` is broken.
    pub fn is_broken(&self, face: u32, side: usize) -> bool {
        self.broken[face as usize] & (1 << side) != 0
    }
}

/// The rest length of a side of a crack that opened at length `length`, of an edge of rest
/// length `rest`: `length - (length - rest)/√2` (stretched or compressed; always positive).
///
/// Why: each side of an opened crack keeps a spring, so that no face corner is held by nothing
/// (without, faces stretched to 1,400 times their rest length after a storm). At `rest`, the
/// two sides would each hold the energy `K_s (l - L0)²/2` the spring had when it broke: the
/// crack would make energy (a review measured a storm step take the springs' energy from 110.7
/// to 123.5 J), and the sides, born over the break limit, would keep the strain scan running
/// every step. At this length the two sides together hold exactly the energy of the spring that
/// broke (`2 · K_s ((l - L0)/√2)²/2`), so a spring that breaks and opens in the same change
/// makes and takes no energy, and each side is stretched by `1/√2` of its extension (under the
/// limit, unless the spring passed √2 times it within one step). An edge that broke earlier
/// without opening gave its energy up then, and its sides take `K_s (l - L0)²/2` back when it
/// opens. The price: their pull together is √2 times the spring's. At their own length (no
/// energy: the crack releases the spring's), the light corners at a crack's rim flew off again
/// (edges 17 to 560 times their rest length in the storm of
/// `faces_keep_their_shape_after_a_fracture_storm`, then UNSTABLE), with or without the
/// pressure of the holes' caps; at half the stiffness and `rest` (the same energy and force)
/// every spring kernel would need a stiffness per spring.
pub(crate) fn opened_side_rest(length: f32, rest: f32) -> f32 {
    length - (length - rest) * std::f32::consts::FRAC_1_SQRT_2
}

/// Side (0..3) of `face` that is edge `edge` in `topology`.
pub(crate) fn side_of(topology: &Topology, face: u32, edge: u32) -> Option<usize> {
    topology.face_edges[face as usize].iter().position(|&e| e == edge)
}

/// True when edge `edge` carries no spring: it still joins two (or more) faces, one of its first
/// two faces marks it broken (on the first side of that face that is the edge). A broken edge
/// whose faces the crack has parted is two edges of one face each, the sides of the crack, and
/// each is a spring like every other edge of the surface: a face keeps its three sides, so no
/// face is left held at a corner by nothing (before, the sides of an opened crack had no spring,
/// and after a fracture storm faces with two free sides stretched without bound).
pub(crate) fn edge_is_broken(topology: &Topology, fracture: Option<&Fracture>, edge: u32) -> bool {
    let Some(fracture) = fracture else { return false };
    topology.edge_face_count[edge as usize] >= 2
        && topology.edge_faces[edge as usize]
            .iter()
            .filter(|&&f| f != crate::mesh::NO_FACE)
            .any(|&f| side_of(topology, f, edge).is_some_and(|side| fracture.is_broken(f, side)))
}

/// The edges that carry no spring, sorted: those [`edge_is_broken`] finds, gathered from the
/// pending broken sides ([`Fracture::pending`]) instead of asking every edge.
fn broken_edges(topology: &Topology, fracture: Option<&Fracture>) -> Vec<u32> {
    let Some(fracture) = fracture else { return Vec::new() };
    let mut broken = Vec::new();
    for &key in &fracture.pending {
        let (f, side) = ((key / 3) as usize, (key % 3) as usize);
        if fracture.broken[f] & (1 << side) != 0 {
            let e = topology.face_edges[f][side];
            // Only as edge_is_broken counts it: from one of the edge's first two faces, on the
            // face's first side along the edge.
            if e != u32::MAX
                && topology.edge_face_count[e as usize] >= 2
                && topology.edge_faces[e as usize].contains(&(f as u32))
                && side_of(topology, f as u32, e) == Some(side)
            {
                broken.push(e);
            }
        }
    }
    broken.sort_unstable();
    broken.dedup();
    broken
}

/// One spring per edge but the broken ones that still join two faces ([`edge_is_broken`]), with
/// rest length `|X_a - X_b|` from the rest positions, or for a side of an opened crack the one
/// it was given when it opened ([`Fracture::opened_rest`]).
/// With `adjacency` built, also the springs around each vertex ([`Adjacency`]).
pub(crate) fn build_springs(
    topology: &Topology,
    fracture: Option<&Fracture>,
    rest: &[Vec3],
    adjacency: Adjacency,
) -> Springs {
    rebuild_springs(topology, fracture, rest, Springs::default(), adjacency)
}

/// [`build_springs`] into the buffers of `springs` (the springs before a topology change): a
/// crack rebuilds all of them, and new buffers of that size (0.8 MB on the issue-5 balloon) are
/// fresh pages the rebuild then faults in one by one.
pub(crate) fn rebuild_springs(
    topology: &Topology,
    fracture: Option<&Fracture>,
    rest: &[Vec3],
    mut springs: Springs,
    adjacency: Adjacency,
) -> Springs {
    let broken = broken_edges(topology, fracture);
    let count = topology.edges.len() - broken.len();
    springs.ends.clear();
    springs.rest.clear();
    springs.ends.reserve(count);
    springs.rest.reserve(count);
    // The edges between the broken ones copied in runs, then the rest lengths in a loop of
    // their own (one loop pushing both took 0.37 ms of the issue-5 balloon's first cracking
    // step, 30k springs; a fracture phase there is about as long as a plain step).
    let mut from = 0;
    springs.one_face.clear();
    for &e in broken.iter().chain(std::iter::once(&(topology.edges.len() as u32))) {
        springs.ends.extend_from_slice(&topology.edges[from..e as usize]);
        if fracture.is_some() {
            springs.one_face.extend(topology.edge_face_count[from..e as usize].iter().map(|&c| c < 2));
        }
        from = e as usize + 1;
    }
    springs.rest.extend(springs.ends.iter().map(|&[a, b]| (rest[b as usize] - rest[a as usize]).length()));
    // The sides of opened cracks at the lengths they opened at. The springs are the edges in
    // order without the broken ones, so edge e's spring is e less the broken edges before it
    // (a search in the few broken edges, not in the springs).
    for &(key, length) in fracture.map_or(&[][..], |f| &f.opened_rest) {
        let e = topology.face_edges[(key / 3) as usize][(key % 3) as usize];
        if e == u32::MAX {
            continue;
        }
        if let Err(before) = broken.binary_search(&e) {
            springs.rest[e as usize - before] = length;
        }
    }
    if adjacency == Adjacency::Built {
        springs.build_adjacency(rest.len());
    }
    springs
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every broken side of a one-face edge gets a rest length once, the first time it is seen
    /// open, and keeps it: the recorded sides stay sorted by key, one entry each, whatever was
    /// known before (rounds with more broken sides and more holes each).
    #[test]
    fn opened_sides_are_recorded_once_each_in_key_order() {
        let mut triangles = crate::mesh::torus_grid(10, 8);
        let vertices = 80;
        let rest: Vec<Vec3> = (0..vertices).map(|k| Vec3::new(k as f32, (k * k % 13) as f32, 0.5 * k as f32)).collect();
        let mut fracture = Fracture::new(vertices, triangles.len());
        let mut state = 7u32;
        let mut random = move || {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
            state >> 16
        };
        let mut first_seen = std::collections::BTreeMap::new();
        for round in 0..6 {
            // The surface stretched further each round: a side recorded earlier would get
            // another length now.
            let x: Vec<Vec3> = rest.iter().map(|&p| p * (1.1 + 0.05 * round as f32)).collect();
            // More holes (faces gone, as degenerate ones with no edges of their own) and more
            // broken sides.
            for _ in 0..4 {
                let f = random() as usize % triangles.len();
                triangles[f] = [0, 0, 0];
            }
            for _ in 0..30 {
                let f = random() as usize % triangles.len();
                fracture.mark(f as u32, (random() % 3) as usize);
            }
            let topology = Topology::build(&triangles, vertices);
            fracture.record_opened_sides(&topology, &x, &rest);
            for (f, &bits) in fracture.broken.iter().enumerate() {
                for side in (0..3).filter(|&side| bits & (1 << side) != 0) {
                    let e = topology.face_edges[f][side];
                    if e != u32::MAX && topology.edge_face_count[e as usize] == 1 {
                        let [a, b] = topology.edges[e as usize].map(|v| v as usize);
                        let length = opened_side_rest((x[b] - x[a]).length(), (rest[b] - rest[a]).length());
                        first_seen.entry(3 * f as u32 + side as u32).or_insert(length);
                    }
                }
            }
            let recorded: Vec<(u32, f32)> = fracture.opened_rest.clone();
            let expected: Vec<(u32, f32)> = first_seen.iter().map(|(&k, &l)| (k, l)).collect();
            assert_eq!(recorded, expected, "round {round}");
        }
        assert!(first_seen.len() >= 10, "only {} opened sides", first_seen.len());
    }

    /// Springs given room by `reserve_headroom` are rebuilt into the same arrays while they
    /// fit (a crack splits vertices and adds edges), with the same springs and adjacency as a
    /// new build; beyond the room they grow as before.
    #[test]
    fn springs_rebuilt_within_their_room_keep_their_arrays() {
        let triangles = crate::mesh::torus_grid(12, 10);
        let vertices = 120;
        let rest: Vec<Vec3> =
            (0..vertices + 40).map(|k| Vec3::new(k as f32, (k * k % 11) as f32, 0.25 * k as f32)).collect();
        let mut springs =
            build_springs(&Topology::build(&triangles, vertices), None, &rest[..vertices], Adjacency::Built);
        springs.reserve_headroom(0.125);
        let arrays = |s: &Springs| {
            [
                s.ends.as_ptr() as usize,
                s.rest.as_ptr() as usize,
                s.offsets.as_ptr() as usize,
                s.adjacency.as_ptr() as usize,
            ]
        };
        let held = arrays(&springs);
        let mut current = triangles.clone();
        // Each round gives one more face corner a new vertex (a split fan: 2 more edges), then
        // rebuilds; 360 edges with room for 45 more.
        for round in 0..40usize {
            current[3 * round][0] = (vertices + round) as u32;
            let count = vertices + round + 1;
            let topology = Topology::build(&current, count);
            let fresh = build_springs(&topology, None, &rest[..count], Adjacency::Built);
            springs = rebuild_springs(&topology, None, &rest[..count], springs, Adjacency::Built);
            assert_eq!(
                (&springs.ends, &springs.rest, &springs.offsets, &springs.adjacency),
                (&fresh.ends, &fresh.rest, &fresh.offsets, &fresh.adjacency),
                "round {round}"
            );
            let room = (360.0f64 * 0.125).ceil() as usize;
            if springs.ends.len() <= 360 + room && count <= vertices + (vertices as f64 * 0.125).ceil() as usize {
                assert_eq!(arrays(&springs), held, "round {round}: an array moved within the room");
            }
        }
        assert!(springs.ends.len() > 360 + 45, "the rounds must outgrow the room: {}", springs.ends.len());
    }

    #[test]
    fn springs_skip_exactly_the_broken_edges() {
        // A torus grid with a few duplicated faces (non-manifold edges, where only the first two
        // faces count), a degenerate one (an edge twice in one face), and a hole (edges of one
        // face, which keep their springs, broken or not).
        let (nu, nv) = (6u32, 5u32);
        let mut triangles = crate::mesh::torus_grid(nu, nv);
        triangles.extend([triangles[3], triangles[7], triangles[7], [0, 1, 0]]);
        triangles.drain(20..24);
        let rest: Vec<Vec3> = (0..nu * nv).map(|k| Vec3::new(k as f32, (k * k % 7) as f32, 0.5 * k as f32)).collect();
        let topology = Topology::build(&triangles, rest.len());
        let mut state = 99u32;
        // Each round's springs are rebuilt into the buffers of the round before (as a crack
        // does): the same springs as a new build.
        let mut previous = build_springs(&topology, None, &rest, Adjacency::Built);
        let (mut border_bits, mut opened_sides) = (0, 0);
        for round in 0..50 {
            let mut fracture = Fracture::new(rest.len(), triangles.len());
            for f in 0..triangles.len() as u32 {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
                let bits = if (state >> 16) % 4 == 0 { (state >> 20) % 8 } else { 0 };
                for side in (0..3).filter(|&side| bits & (1 << side) != 0) {
                    fracture.mark(f, side);
                }
            }
            // Rest lengths of their own for the sides of the hole (as opened cracks have them),
            // each after broken edges and before others: the spring of each is found from its
            // edge.
            let mut opened = std::collections::BTreeMap::new();
            for e in (0..topology.edges.len()).filter(|&e| topology.edge_face_count[e] == 1) {
                let f = topology.edge_faces[e][0];
                if let Some(side) = side_of(&topology, f, e as u32).filter(|_| (state >> (e % 13)) & 1 == 1) {
                    opened.insert(3 * f + side as u32, (e, 100.0 + e as f32 + round as f32 / 64.0));
                }
            }
            fracture.opened_rest = opened.iter().map(|(&key, &(_, length))| (key, length)).collect();
            let springs = build_springs(&topology, Some(&fracture), &rest, Adjacency::Built);
            let reused =
                rebuild_springs(&topology, Some(&fracture), &rest, std::mem::take(&mut previous), Adjacency::Built);
            assert_eq!(
                (&reused.ends, &reused.rest, &reused.offsets, &reused.adjacency, &reused.one_face),
                (&springs.ends, &springs.rest, &springs.offsets, &springs.adjacency, &springs.one_face),
                "round {round}"
            );
            previous = reused;
            // The fracture check skips exactly the springs on edges of one face (non-manifold
            // edges, of three faces here, may break).
            assert_eq!(springs.one_face.len(), springs.ends.len(), "round {round}");
            for (k, ends) in springs.ends.iter().enumerate() {
                let e = topology.edges.binary_search(ends).unwrap();
                assert_eq!(springs.may_break(k), topology.edge_face_count[e] >= 2, "round {round}: spring {k}");
            }
            let expected: Vec<[u32; 2]> = (0..topology.edges.len() as u32)
                .filter(|&e| !edge_is_broken(&topology, Some(&fracture), e))
                .map(|e| topology.edges[e as usize])
                .collect();
            assert_eq!(springs.ends, expected, "round {round}");
            let border = (0..topology.edges.len()).filter(|&e| topology.edge_face_count[e] == 1);
            assert!(border.clone().count() >= 6);
            border_bits += border
                .clone()
                .filter(|&e| {
                    let f = topology.edge_faces[e][0];
                    side_of(&topology, f, e as u32).is_some_and(|side| fracture.is_broken(f, side))
                })
                .count();
            for e in border {
                assert!(springs.ends.contains(&topology.edges[e]), "round {round}: border edge {e} lost its spring");
            }
            assert!(springs.ends.len() < topology.edges.len(), "round {round}: some springs must break");
            let own: std::collections::HashMap<[u32; 2], f32> =
                opened.values().map(|&(e, length)| (topology.edges[e], length)).collect();
            for (&[a, b], &l) in springs.ends.iter().zip(&springs.rest) {
                let length = own.get(&[a, b]).copied().unwrap_or((rest[b as usize] - rest[a as usize]).length());
                assert_eq!(l, length, "round {round}: spring {a}-{b}");
            }
            opened_sides += own.len();
        }
        assert!(opened_sides > 20, "only {opened_sides} sides had rest lengths of their own");
        assert!(border_bits > 0, "no round marked a border side broken");
        let without_fracture = build_springs(&topology, None, &rest, Adjacency::Built);
        assert_eq!(without_fracture.ends, topology.edges);
        // No fracture bookkeeping, no flags: every spring may break.
        assert!(without_fracture.one_face.is_empty());
        assert!((0..without_fracture.len()).all(|k| without_fracture.may_break(k)));
    }
}
