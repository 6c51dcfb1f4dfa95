//! The body's changing surface: vertex state (structure of arrays), the fracture bookkeeping,
//! and rebuilding springs and fragments from the triangles after a topology change.

use glam::Vec3;

use super::springs::Springs;
use crate::mesh::Topology;

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
#[derive(Clone, Debug, Default)]
pub(crate) struct Fracture {
    /// Per face, bit k set when side k (corner k to corner k+1) is a broken spring.
    pub broken: Vec<u8>,
    /// Per vertex, the input-mesh vertex it was split from.
    pub origin: Vec<u32>,
}

impl Fracture {
    pub fn new(vertex_count: usize, face_count: usize) -> Self {
        Self { broken: vec![0; face_count], origin: (0..vertex_count as u32).collect() }
    }

    pub fn memory_bytes(&self) -> usize {
        self.broken.capacity() + self.origin.capacity() * 4
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

/// Side (0..3) of `face` that is edge `edge` in `topology`.
pub(crate) fn side_of(topology: &Topology, face: u32, edge: u32) -> Option<usize> {
    topology.face_edges[face as usize].iter().position(|&e| e == edge)
}

/// True when edge `edge` carries no spring (one of its faces marks it broken).
pub(crate) fn edge_is_broken(topology: &Topology, fracture: Option<&Fracture>, edge: u32) -> bool {
    let Some(fracture) = fracture else { return false };
    topology.edge_faces[edge as usize]
        .iter()
        .filter(|&&f| f != crate::mesh::NO_FACE)
        .any(|&f| side_of(topology, f, edge).is_some_and(|side| fracture.is_broken(f, side)))
}

/// One spring per unbroken edge, with rest length `|X_a - X_b|` from the rest positions.
pub(crate) fn build_springs(topology: &Topology, fracture: Option<&Fracture>, rest: &[Vec3]) -> Springs {
    let mut springs = Springs::default();
    for (e, &[a, b]) in topology.edges.iter().enumerate() {
        if edge_is_broken(topology, fracture, e as u32) {
            continue;
        }
        springs.ends.push([a, b]);
        springs.rest.push((rest[b as usize] - rest[a as usize]).length());
    }
    springs.build_adjacency(rest.len());
    springs
}
