//! Flat rest data of the shell's three constraint kinds, built once and stored sorted by colour
//! (constraints of one colour touch disjoint vertices and are contiguous, so a colour is one
//! index range that runs in parallel).

use glam::{Vec2, Vec3};

use super::settings::AnisotropySettings;
use crate::error::{Error, Result};
use crate::material::Mat32;
use crate::mesh::Topology;
use crate::solver::{bending_rest, colour_constraints, triangle_rest};

fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

/// Membrane constraints (SPEC 1.3), one per triangle, sorted by colour.
#[derive(Debug, Default)]
pub(crate) struct Membranes {
    pub tri: Vec<[u32; 3]>,
    pub dm_inv: Vec<[f32; 4]>,
    pub area: Vec<f32>,
    /// Rest-plane basis: only for the linear material (empty otherwise).
    pub basis: Vec<Mat32>,
    /// The mesh triangle of each constraint.
    pub face: Vec<u32>,
    /// Inverse masses of the three corners (fixed), so projections gather no masses.
    pub inv_mass: Vec<[f32; 3]>,
    /// Colour c is `colours[c]..colours[c + 1]`.
    pub colours: Vec<usize>,
}

impl Membranes {
    pub(crate) fn build(rest: &[Vec3], triangles: &[[u32; 3]], keep_basis: bool) -> Result<Self> {
        let (order, colours) = colour_constraints(triangles, rest.len());
        let mut m = Membranes { colours, ..Default::default() };
        m.tri.reserve_exact(order.len());
        m.dm_inv.reserve_exact(order.len());
        m.area.reserve_exact(order.len());
        m.face.reserve_exact(order.len());
        if keep_basis {
            m.basis.reserve_exact(order.len());
        }
        for &t in &order {
            let tri = triangles[t as usize];
            let [a, b, c] = tri.map(|v| rest[v as usize]);
            let r = triangle_rest(a, b, c).ok_or_else(|| {
                Error::invalid_mesh(format!(
                    "the shell needs non-degenerate triangles: triangle {t} ({}, {}, {}) is too thin to define a strain (its area is below 1e-12 of its longest side squared)",
                    tri[0], tri[1], tri[2]
                ))
            })?;
            m.tri.push(tri);
            m.dm_inv.push(r.dm_inv);
            m.area.push(r.area);
            m.face.push(t);
            if keep_basis {
                m.basis.push(r.basis);
            }
        }
        Ok(m)
    }

    pub(crate) fn len(&self) -> usize {
        self.tri.len()
    }

    /// Copies the corners' inverse masses next to each constraint.
    pub(crate) fn set_inverse_masses(&mut self, inv_mass: &[f32]) {
        self.inv_mass = self.tri.iter().map(|t| t.map(|v| inv_mass[v as usize])).collect();
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        vec_bytes(&self.tri)
            + vec_bytes(&self.dm_inv)
            + vec_bytes(&self.area)
            + vec_bytes(&self.basis)
            + vec_bytes(&self.face)
            + vec_bytes(&self.inv_mass)
            + vec_bytes(&self.colours)
    }
}

/// Bending stencils (SPEC 1.4), one per interior edge, sorted by colour.
#[derive(Debug, Default)]
pub(crate) struct Bendings {
    /// `(x0, x1, x2, x3)`: the edge, then the opposite vertices.
    pub idx: Vec<[u32; 4]>,
    pub k: Vec<[f32; 4]>,
    /// `w_i K_i` and `Σ w_i K_i²` (inverse masses are fixed), so projections gather no masses.
    pub wk: Vec<[f32; 4]>,
    pub wk2: Vec<f32>,
    pub q: Vec<f32>,
    /// Rest `Σ K_i X_i` in the stencil frame: only for the rest-preserving model.
    pub rest_local: Vec<Vec3>,
    /// That vector carried by the stencil's frame at the start of the substep, held through the
    /// iterations (scratch; only for the rest-preserving model).
    pub target: Vec<Vec3>,
    pub colours: Vec<usize>,
}

impl Bendings {
    pub(crate) fn build(rest: &[Vec3], triangles: &[[u32; 3]], topology: &Topology, keep_rest: bool) -> Self {
        let opposite =
            |face: u32, a: u32, b: u32| triangles[face as usize].into_iter().find(|&v| v != a && v != b).unwrap_or(a);
        let mut stencils = Vec::with_capacity(topology.edges.len());
        let mut rests = Vec::with_capacity(topology.edges.len());
        for (e, &[a, b]) in topology.edges.iter().enumerate() {
            if topology.edge_face_count[e] != 2 {
                continue;
            }
            let [f0, f1] = topology.edge_faces[e];
            let idx = [a, b, opposite(f0, a, b), opposite(f1, a, b)];
            if let Some(r) = bending_rest(idx.map(|v| rest[v as usize])) {
                stencils.push(idx);
                rests.push(r);
            }
        }
        let (order, colours) = colour_constraints(&stencils, rest.len());
        let mut s = Bendings { colours, ..Default::default() };
        s.idx.reserve_exact(order.len());
        s.k.reserve_exact(order.len());
        s.q.reserve_exact(order.len());
        if keep_rest {
            s.rest_local.reserve_exact(order.len());
            s.target = vec![Vec3::ZERO; order.len()];
        }
        for &i in &order {
            let r = &rests[i as usize];
            s.idx.push(stencils[i as usize]);
            s.k.push(r.k);
            s.q.push(r.q);
            if keep_rest {
                s.rest_local.push(r.rest_local);
            }
        }
        s
    }

    pub(crate) fn len(&self) -> usize {
        self.idx.len()
    }

    /// Precomputes the mass-weighted coefficients from the inverse masses.
    pub(crate) fn set_inverse_masses(&mut self, inv_mass: &[f32]) {
        self.wk = self
            .idx
            .iter()
            .zip(&self.k)
            .map(|(idx, k)| [0, 1, 2, 3].map(|j| inv_mass[idx[j] as usize] * k[j]))
            .collect();
        self.wk2 = self.wk.iter().zip(&self.k).map(|(wk, k)| (0..4).map(|j| wk[j] * k[j]).sum()).collect();
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        vec_bytes(&self.idx)
            + vec_bytes(&self.k)
            + vec_bytes(&self.wk)
            + vec_bytes(&self.wk2)
            + vec_bytes(&self.q)
            + vec_bytes(&self.rest_local)
            + vec_bytes(&self.target)
            + vec_bytes(&self.colours)
    }
}

/// One anisotropic region as added by the caller.
#[derive(Debug, Clone)]
pub(crate) struct Region {
    pub faces: Vec<u32>,
    pub settings: AnisotropySettings,
}

/// Anisotropic constraints (SPEC 1.5), one per face of each region, sorted by colour. Exists
/// only once a region has been added.
#[derive(Debug, Default)]
pub(crate) struct Anisotropics {
    pub tri: Vec<[u32; 3]>,
    pub dm_inv: Vec<[f32; 4]>,
    pub area: Vec<f32>,
    /// Unit fibre direction in the rest basis (t1, t2).
    pub dir: Vec<Vec2>,
    /// Index into `params`.
    pub region: Vec<u32>,
    pub params: Vec<AnisotropySettings>,
    pub colours: Vec<usize>,
}

/// The fibre direction of a face: the caller's direction projected into the rest plane, or when
/// none is given (or it is normal to the face) the direction from the face's centroid towards the
/// region's centroid projected into the plane (fibres converge on the region's centre), or the
/// first rest edge when that is degenerate too.
fn fibre(basis: &Mat32, given: Vec3, towards_centre: Vec3) -> Vec2 {
    for d in [given, towards_centre] {
        let a = Vec2::new(basis.c0.dot(d), basis.c1.dot(d));
        if a.length() > 1e-6 * d.length().max(f32::MIN_POSITIVE) && a.length() > 0.0 {
            return a.normalize();
        }
    }
    Vec2::X
}

impl Anisotropics {
    pub(crate) fn build(rest: &[Vec3], triangles: &[[u32; 3]], regions: &[Region]) -> Self {
        let mut tris = Vec::new();
        let mut entries = Vec::new();
        for (r, region) in regions.iter().enumerate() {
            let centre = region
                .faces
                .iter()
                .map(|&f| triangles[f as usize].iter().map(|&v| rest[v as usize]).sum::<Vec3>() / 3.0)
                .sum::<Vec3>()
                / region.faces.len().max(1) as f32;
            for &f in &region.faces {
                let tri = triangles[f as usize];
                let [a, b, c] = tri.map(|v| rest[v as usize]);
                // Faces were checked non-degenerate when the shell was made.
                let Some(tr) = triangle_rest(a, b, c) else { continue };
                let dir = fibre(&tr.basis, region.settings.direction, centre - (a + b + c) / 3.0);
                tris.push(tri);
                entries.push((tr, dir, r as u32));
            }
        }
        let (order, colours) = colour_constraints(&tris, rest.len());
        let mut s =
            Anisotropics { colours, params: regions.iter().map(|r| r.settings).collect(), ..Default::default() };
        for &i in &order {
            let (tr, dir, region) = entries[i as usize];
            s.tri.push(tris[i as usize]);
            s.dm_inv.push(tr.dm_inv);
            s.area.push(tr.area);
            s.dir.push(dir);
            s.region.push(region);
        }
        s
    }

    pub(crate) fn len(&self) -> usize {
        self.tri.len()
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        vec_bytes(&self.tri)
            + vec_bytes(&self.dm_inv)
            + vec_bytes(&self.area)
            + vec_bytes(&self.dir)
            + vec_bytes(&self.region)
            + vec_bytes(&self.params)
            + vec_bytes(&self.colours)
    }
}

/// Edge-distance constraints (the paper's baseline), one per edge, sorted by colour. Built only
/// for the distance solver.
#[derive(Debug, Default)]
pub(crate) struct Edges {
    pub idx: Vec<[u32; 2]>,
    pub rest: Vec<f32>,
    pub colours: Vec<usize>,
}

impl Edges {
    pub(crate) fn build(rest: &[Vec3], topology: &Topology) -> Self {
        let (order, colours) = colour_constraints(&topology.edges, rest.len());
        let idx: Vec<[u32; 2]> = order.iter().map(|&e| topology.edges[e as usize]).collect();
        let lengths = idx.iter().map(|&[a, b]| (rest[b as usize] - rest[a as usize]).length()).collect();
        Edges { idx, rest: lengths, colours }
    }

    pub(crate) fn len(&self) -> usize {
        self.idx.len()
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        vec_bytes(&self.idx) + vec_bytes(&self.rest) + vec_bytes(&self.colours)
    }
}
