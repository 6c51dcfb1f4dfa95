//! Where the particles are (SPEC 3): the columns x rows lattice, its mask of holes, the numbering
//! of particles, their rest positions and the triangulated grid used for output.
//!
//! Sites are numbered row-major (`site = row * columns + column`); particles are the sites the
//! mask keeps, numbered in the same order with holes skipped. At rest particle (column, row)
//! sits at `(column * spacing, 0, row * spacing)`: the sheet lies in the x-z plane, normal +y.

use crate::error::{Error, Result};

/// Marks a site that holds no particle.
pub(crate) const HOLE: u32 = u32::MAX;

/// The lattice, its mask and its numbering.
#[derive(Clone, Debug)]
pub struct LatticeLayout {
    columns: usize,
    rows: usize,
    spacing: f64,
    particle_of_site: Vec<u32>,
    site_of_particle: Vec<u32>,
}

impl LatticeLayout {
    /// A lattice of `columns x rows` sites; `mask` (row-major, `columns * rows` bytes, 1 =
    /// particle, 0 = hole) or `None` for a full sheet. Any other mask value, a mask of the wrong
    /// length or a mask without a particle is an error naming the problem.
    pub fn new(columns: u32, rows: u32, spacing: f32, mask: Option<&[u8]>) -> Result<Self> {
        let (columns, rows) = (columns as usize, rows as usize);
        let sites = columns * rows;
        let mut particle_of_site = Vec::with_capacity(sites);
        let mut site_of_particle = Vec::new();
        match mask {
            None => {
                particle_of_site.extend(0..sites as u32);
                site_of_particle.extend(0..sites as u32);
            }
            Some(mask) => {
                if mask.len() != sites {
                    return Err(Error::invalid_argument(format!(
                        "`mask` has {} entries but the lattice has columns x rows = {columns} x {rows} = {sites} sites",
                        mask.len()
                    )));
                }
                for (site, &m) in mask.iter().enumerate() {
                    match m {
                        0 => particle_of_site.push(HOLE),
                        1 => {
                            particle_of_site.push(site_of_particle.len() as u32);
                            site_of_particle.push(site as u32);
                        }
                        other => {
                            return Err(Error::invalid_argument(format!(
                                "`mask`[{site}] (column {}, row {}) = {other}: use 1 for a particle and 0 for a hole",
                                site % columns,
                                site / columns
                            )));
                        }
                    }
                }
                if site_of_particle.is_empty() {
                    return Err(Error::invalid_argument(
                        "`mask` holds no particle (every entry is 0): at least one entry must be 1",
                    ));
                }
            }
        }
        Ok(Self { columns, rows, spacing: spacing as f64, particle_of_site, site_of_particle })
    }

    /// Sites along x.
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Sites along z.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Rest distance between neighbours, m.
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// `columns * rows`.
    pub fn site_count(&self) -> usize {
        self.particle_of_site.len()
    }

    /// Number of particles (sites that are not holes).
    pub fn particle_count(&self) -> usize {
        self.site_of_particle.len()
    }

    /// The site at (column, row), or an error naming the coordinates when outside the lattice.
    pub fn site(&self, column: u32, row: u32) -> Result<usize> {
        if column as usize >= self.columns || row as usize >= self.rows {
            return Err(Error::invalid_argument(format!(
                "(column {column}, row {row}) is outside the lattice of {} columns x {} rows",
                self.columns, self.rows
            )));
        }
        Ok(row as usize * self.columns + column as usize)
    }

    /// The particle at (column, row), or an error when it is outside the lattice or a hole.
    pub fn particle(&self, column: u32, row: u32) -> Result<usize> {
        let site = self.site(column, row)?;
        match self.particle_of_site[site] {
            HOLE => Err(Error::invalid_argument(format!(
                "(column {column}, row {row}) is a hole of the mask, not a particle"
            ))),
            p => Ok(p as usize),
        }
    }

    /// True when `site` holds a particle.
    #[inline]
    pub fn is_particle(&self, site: usize) -> bool {
        self.particle_of_site[site] != HOLE
    }

    /// The site of particle `p`.
    #[inline]
    pub fn site_of_particle(&self, p: usize) -> usize {
        self.site_of_particle[p] as usize
    }

    /// Rest position of `site` in world space, m.
    pub fn rest_position(&self, site: usize) -> [f64; 3] {
        let (c, r) = (site % self.columns, site / self.columns);
        [c as f64 * self.spacing, 0.0, r as f64 * self.spacing]
    }

    /// Rest (x, z) of `site` relative to the centre of the lattice: the rest coordinates used by
    /// the region sums, centred so that `A = sum m x x0^T - M c c0^T` cancels as little as possible.
    #[inline]
    pub(crate) fn centred_rest(&self, column: usize, row: usize) -> [f64; 2] {
        [
            (column as f64 - 0.5 * (self.columns as f64 - 1.0)) * self.spacing,
            (row as f64 - 0.5 * (self.rows as f64 - 1.0)) * self.spacing,
        ]
    }

    /// The triangulated grid over the particles (indices are particle numbers), counter-clockwise
    /// seen from +y. A cell with four particles gives two triangles, a cell with three gives one.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let mut tris = Vec::with_capacity(self.triangle_count());
        self.for_each_triangle(|t| tris.push(t));
        tris
    }

    /// Number of triangles of [`Self::triangles`], without building them.
    pub fn triangle_count(&self) -> usize {
        let mut count = 0;
        self.for_each_triangle(|_| count += 1);
        count
    }

    fn for_each_triangle(&self, mut emit: impl FnMut([u32; 3])) {
        if self.columns < 2 || self.rows < 2 {
            return;
        }
        for r in 0..self.rows - 1 {
            for c in 0..self.columns - 1 {
                let at = |dc: usize, dr: usize| self.particle_of_site[(r + dr) * self.columns + c + dc];
                let (a, b, cc, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
                match [a != HOLE, b != HOLE, cc != HOLE, d != HOLE] {
                    [true, true, true, true] => {
                        emit([a, cc, b]);
                        emit([b, cc, d]);
                    }
                    [false, true, true, true] => emit([b, cc, d]),
                    [true, false, true, true] => emit([a, cc, d]),
                    [true, true, false, true] => emit([a, d, b]),
                    [true, true, true, false] => emit([a, cc, b]),
                    _ => {}
                }
            }
        }
    }

    /// Heap bytes held.
    pub fn memory_bytes(&self) -> usize {
        (self.particle_of_site.capacity() + self.site_of_particle.capacity()) * std::mem::size_of::<u32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbering_skips_holes_and_triangles_face_up() {
        let mask = [1, 1, 1, 1, 0, 1, 1, 1, 1];
        let l = LatticeLayout::new(3, 3, 0.5, Some(&mask)).unwrap();
        assert_eq!(l.particle_count(), 8);
        assert_eq!(l.particle(2, 1).unwrap(), 4);
        assert!(l.particle(1, 1).unwrap_err().message.contains("hole"));
        assert!(l.site(3, 0).is_err());
        let tris = l.triangles();
        assert_eq!(tris.len(), 4, "each cell touching the hole keeps one triangle");
        let pos = |p: u32| l.rest_position(l.site_of_particle(p as usize));
        for t in &tris {
            let [a, b, c] = t.map(pos);
            let e1 = [b[0] - a[0], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[2] - a[2]];
            // y component of e1 x e2 = e1.z e2.x - e1.x e2.z
            assert!(e1[1] * e2[0] - e1[0] * e2[1] > 0.0, "{t:?} must face +y");
        }
        let full = LatticeLayout::new(4, 3, 1.0, None).unwrap();
        assert_eq!(full.triangles().len(), 2 * 3 * 2);
        assert_eq!(full.triangle_count(), 12);
        assert_eq!(l.triangle_count(), 4);
    }

    #[test]
    fn bad_masks_are_refused() {
        assert!(LatticeLayout::new(2, 2, 1.0, Some(&[0, 0, 0, 0])).unwrap_err().message.contains("no particle"));
        assert!(LatticeLayout::new(2, 2, 1.0, Some(&[0, 7, 0, 0])).unwrap_err().message.contains("`mask`[1]"));
        assert!(LatticeLayout::new(2, 2, 1.0, Some(&[1, 1, 1])).is_err());
    }
}
