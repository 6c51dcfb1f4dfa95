//! Collision detection (SPEC 1.6): exact, conservative continuous collision queries in f64.
//!
//! Owns the standalone vertex-triangle and edge-edge queries, the broad phase over a moving
//! triangle mesh ([`bvh`], [`candidates`]) and the self-contact of a moving mesh with its contact constraints ([`self_contact`]).
//! Knows nothing of the FFI or of any simulator.
//!
//! A query runs three stages, cheapest first, each of which may only say "certainly no contact"
//! or "maybe":
//! 1. [`filters::swept_aabbs_separated`]: the boxes swept by the two primitives over the step are
//!    more than the thickness apart on some axis (exact comparisons on the inputs).
//! 2. [`filters::plane_distance_filter`]: the deforming non-penetration filter of Tang et al. 2010
//!    extended to a thickness: the coplanarity cubic, in Bernstein form, keeps one sign with a
//!    margin larger than its floating-point error bound and than `thickness * |n(t)|`.
//! 3. [`inclusion`]: an inclusion-based root finder in the spirit of Tight-Inclusion (Wang et al.
//!    2021): the gap function is multilinear in (t, u, v), so its values on a sub-box lie in the
//!    hull of its corner values; corners are evaluated in f64 with a rigorous error bound, boxes
//!    that cannot contain a contact are dropped, the rest are bisected depth first, earliest time
//!    first, with a fixed budget of boxes. When the budget runs out the answer is a hit at the
//!    earliest time not yet ruled out, so the query never misses and never runs long.

pub mod bvh;
pub mod candidates;
pub mod ccd;
pub mod filters;
pub mod hull_filter;
pub mod inclusion;
pub mod self_contact;

pub use bvh::{Aabb, Bvh};
pub use candidates::{Candidates, MeshBroadPhase};
pub use ccd::{CcdOutcome, CcdSettings, Stage, edge_edge, edge_edge_with, vertex_triangle, vertex_triangle_with};
pub use self_contact::{ContactCounts, SelfContact};
