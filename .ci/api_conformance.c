/* Compile-only check that include/softshell.h provides the names and field types that
   the softshell C ABI contract (API.md) fixes. It is not a behaviour test; it runs nothing.
     cc -std=c99 -Wall -Werror -fsyntax-only -I include .ci/api_conformance.c
   Check only the parts that exist so far with -DONLY_MESH, -DONLY_SHELL, ... (several allowed). */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include "softshell.h"

#if !defined(ONLY_MESH) && !defined(ONLY_SHELL) && !defined(ONLY_CCD) && !defined(ONLY_BODY) && !defined(ONLY_LATTICE)
#define ONLY_MESH
#define ONLY_SHELL
#define ONLY_CCD
#define ONLY_BODY
#define ONLY_LATTICE
#endif

#define HAS(fn) (void)(fn)

void conformance(void);
void conformance(void) {
  SoftshellStatus st = SOFTSHELL_STATUS_OK;
  uint32_t codes[] = {SOFTSHELL_STATUS_OK, SOFTSHELL_STATUS_NULL_ARGUMENT, SOFTSHELL_STATUS_INVALID_ARGUMENT,
                      SOFTSHELL_STATUS_INVALID_MESH, SOFTSHELL_STATUS_IO, SOFTSHELL_STATUS_BUFFER_TOO_SMALL,
                      SOFTSHELL_STATUS_UNSTABLE, SOFTSHELL_STATUS_UNSUPPORTED, SOFTSHELL_STATUS_POISONED,
                      SOFTSHELL_STATUS_INTERNAL};
  (void)st; (void)codes;
  uint32_t (*abi)(void) = softshell_abi_version; (void)abi;
  const char *(*ver)(void) = softshell_version_string; (void)ver;
  const char *(*name)(uint32_t) = softshell_status_name; (void)name;
  const char *(*err)(void) = softshell_last_error; (void)err;
  int major = SOFTSHELL_VERSION_MAJOR, minor = SOFTSHELL_VERSION_MINOR, patch = SOFTSHELL_VERSION_PATCH;
  (void)major; (void)minor; (void)patch;

#ifdef ONLY_MESH
  SoftshellStatus (*from_arrays)(const float *, size_t, const uint32_t *, size_t, SoftshellMesh **) = softshell_mesh_from_arrays;
  SoftshellStatus (*load)(const char *, SoftshellMesh **) = softshell_mesh_load_obj;
  SoftshellStatus (*save)(const SoftshellMesh *, const char *) = softshell_mesh_save_obj;
  void (*mfree)(SoftshellMesh *) = softshell_mesh_free;
  size_t (*mv)(const SoftshellMesh *) = softshell_mesh_vertex_count;
  size_t (*mt)(const SoftshellMesh *) = softshell_mesh_triangle_count;
  SoftshellStatus (*rep)(const SoftshellMesh *, SoftshellMeshReport *) = softshell_mesh_report;
  (void)from_arrays; (void)load; (void)save; (void)mfree; (void)mv; (void)mt; (void)rep;
  SoftshellMeshReport r;
  size_t *sz[] = {&r.vertex_count, &r.edge_count, &r.triangle_count, &r.boundary_edges, &r.non_manifold_edges,
                  &r.degenerate_triangles, &r.components};
  int32_t *g = &r.genus; bool *b1 = &r.is_closed, *b2 = &r.is_consistently_oriented;
  double *d1 = &r.area, *d2 = &r.volume; float *f1 = r.bbox_min, *f2 = r.bbox_max;
  (void)sz; (void)g; (void)b1; (void)b2; (void)d1; (void)d2; (void)f1; (void)f2;
#endif

#ifdef ONLY_SHELL
  SoftshellShellDef d = softshell_shell_def_default();
  float *ff[] = {&d.time_step, &d.pressure, &d.youngs_modulus, &d.poisson_ratio, &d.thickness, &d.density,
                 &d.bending_coefficient, &d.damping, &d.stop_volume_ratio, &d.collision_thickness};
  uint32_t *uu[] = {&d.substeps, &d.iterations, &d.solver, &d.material, &d.bending, &d.threads};
  bool *coll = &d.collisions;
  (void)ff; (void)uu; (void)coll;
  uint32_t kinds[] = {SOFTSHELL_SOLVER_XPBD, SOFTSHELL_SOLVER_PBD, SOFTSHELL_MATERIAL_STVK, SOFTSHELL_MATERIAL_COROTATED,
                      SOFTSHELL_MATERIAL_LINEAR, SOFTSHELL_MATERIAL_NEO_HOOKEAN, SOFTSHELL_MATERIAL_MOONEY_RIVLIN,
                      SOFTSHELL_BENDING_ISOMETRIC_REST, SOFTSHELL_BENDING_ISOMETRIC, SOFTSHELL_BENDING_NONE,
                      SOFTSHELL_ANISOTROPY_ARAP, SOFTSHELL_ANISOTROPY_STVK, SOFTSHELL_ANISOTROPY_SQRT,
                      SOFTSHELL_CURVATURE_MEAN, SOFTSHELL_CURVATURE_GAUSSIAN};
  (void)kinds;
  SoftshellAnisotropyDef a = softshell_anisotropy_def_default();
  uint32_t *ae = &a.energy; float *af[] = {&a.stiffness, &a.inward_push, &a.target_stretch}; float *adir = a.direction;
  (void)ae; (void)af; (void)adir;
  SoftshellStatus (*snew)(const SoftshellMesh *, const SoftshellShellDef *, SoftshellShell **) = softshell_shell_new;
  void (*sfree)(SoftshellShell *) = softshell_shell_free;
  SoftshellStatus (*region)(SoftshellShell *, const uint32_t *, size_t, const SoftshellAnisotropyDef *) = softshell_shell_add_anisotropic_region;
  SoftshellStatus (*sstep)(SoftshellShell *, SoftshellShellStats *) = softshell_shell_step;
  size_t (*svc)(const SoftshellShell *) = softshell_shell_vertex_count;
  SoftshellStatus (*scp)(const SoftshellShell *, float *, size_t, size_t *) = softshell_shell_copy_positions;
  SoftshellStatus (*sce)(const SoftshellShell *, float *, size_t, size_t *) = softshell_shell_copy_face_energy;
  SoftshellStatus (*scc)(const SoftshellShell *, uint32_t, float *, size_t, size_t *) = softshell_shell_copy_vertex_curvature;
  size_t (*smem)(const SoftshellShell *) = softshell_shell_memory_bytes;
  (void)snew; (void)sfree; (void)region; (void)sstep; (void)svc; (void)scp; (void)sce; (void)scc; (void)smem;
  SoftshellShellStats s;
  uint64_t *su[] = {&s.step, &s.collision_candidates, &s.ccd_tests, &s.contacts};
  double *sd[] = {&s.time, &s.volume, &s.volume_ratio, &s.residual, &s.elastic_energy, &s.bending_energy,
                  &s.anisotropic_energy, &s.step_seconds};
  bool *fin = &s.finished;
  (void)su; (void)sd; (void)fin;
#endif

#ifdef ONLY_CCD
  SoftshellStatus (*vt)(const double[3], const double[3], const double[3], const double[3], const double[3],
                        const double[3], const double[3], const double[3], double, int32_t *, double *) = softshell_ccd_vertex_triangle;
  SoftshellStatus (*ee)(const double[3], const double[3], const double[3], const double[3], const double[3],
                        const double[3], const double[3], const double[3], double, int32_t *, double *) = softshell_ccd_edge_edge;
  (void)vt; (void)ee;
#endif

#ifdef ONLY_BODY
  SoftshellBodyDef bd = softshell_body_def_default();
  float *bf[] = {&bd.time_step, &bd.total_mass, &bd.spring_stiffness, &bd.spring_damping, &bd.gas_amount, &bd.drag,
                 &bd.break_strain, &bd.break_force, &bd.leak_rate, &bd.ground_height, &bd.restitution, &bd.friction};
  float *bv[] = {bd.gravity, bd.wind};
  uint32_t *bu[] = {&bd.substeps, &bd.integrator, &bd.threads};
  bool *gr = &bd.ground;
  (void)bf; (void)bv; (void)bu; (void)gr;
  uint32_t ik[] = {SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
                   SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, SOFTSHELL_INTEGRATOR_XPBD};
  (void)ik;
  SoftshellStatus (*bnew)(const SoftshellMesh *, const SoftshellBodyDef *, SoftshellBody **) = softshell_body_new;
  void (*bfree)(SoftshellBody *) = softshell_body_free;
  SoftshellStatus (*sph)(SoftshellBody *, const float[3], float) = softshell_body_add_sphere_obstacle;
  SoftshellStatus (*pl)(SoftshellBody *, const float[3], const float[3]) = softshell_body_add_plane_obstacle;
  SoftshellStatus (*pin)(SoftshellBody *, uint32_t) = softshell_body_pin_vertex;
  SoftshellStatus (*imp)(SoftshellBody *, uint32_t, const float[3]) = softshell_body_apply_impulse;
  SoftshellStatus (*brk)(SoftshellBody *, uint32_t, uint32_t) = softshell_body_break_edge;
  SoftshellStatus (*bstep)(SoftshellBody *, SoftshellBodyStats *) = softshell_body_step;
  uint64_t (*gen)(const SoftshellBody *) = softshell_body_topology_generation;
  size_t (*bc[])(const SoftshellBody *) = {softshell_body_vertex_count, softshell_body_triangle_count,
                                          softshell_body_fragment_count, softshell_body_memory_bytes};
  SoftshellStatus (*bp)(const SoftshellBody *, float *, size_t, size_t *) = softshell_body_copy_positions;
  SoftshellStatus (*bu32[])(const SoftshellBody *, uint32_t *, size_t, size_t *) = {
      softshell_body_copy_triangles, softshell_body_copy_vertex_origins, softshell_body_copy_fragment_ids};
  (void)bnew; (void)bfree; (void)sph; (void)pl; (void)pin; (void)imp; (void)brk; (void)bstep; (void)gen; (void)bc;
  (void)bp; (void)bu32;
  SoftshellBodyStats bs;
  uint64_t *bsu[] = {&bs.step, &bs.springs_broken, &bs.cores_released, &bs.topology_generation};
  double *bsd[] = {&bs.time, &bs.volume, &bs.pressure, &bs.kinetic_energy, &bs.energy_drift, &bs.step_seconds};
  size_t *bss[] = {&bs.vertex_count, &bs.triangle_count, &bs.fragment_count};
  (void)bsu; (void)bsd; (void)bss;
#endif

#ifdef ONLY_LATTICE
  SoftshellLatticeDef ld = softshell_lattice_def_default();
  uint32_t *lu[] = {&ld.columns, &ld.rows, &ld.region_half_width, &ld.threads};
  float *lf[] = {&ld.spacing, &ld.stiffness, &ld.damping, &ld.time_step, &ld.particle_mass};
  float *lg = ld.gravity;
  (void)lu; (void)lf; (void)lg;
  SoftshellStatus (*lnew)(const SoftshellLatticeDef *, const uint8_t *, SoftshellLattice **) = softshell_lattice_new;
  void (*lfree)(SoftshellLattice *) = softshell_lattice_free;
  SoftshellStatus (*lpin)(SoftshellLattice *, uint32_t, uint32_t) = softshell_lattice_pin;
  SoftshellStatus (*lforce)(SoftshellLattice *, uint32_t, uint32_t, const float[3]) = softshell_lattice_apply_force;
  SoftshellStatus (*lstep)(SoftshellLattice *, SoftshellLatticeStats *) = softshell_lattice_step;
  size_t (*lcount)(const SoftshellLattice *) = softshell_lattice_particle_count;
  SoftshellStatus (*lcp)(const SoftshellLattice *, float *, size_t, size_t *) = softshell_lattice_copy_positions;
  (void)lnew; (void)lfree; (void)lpin; (void)lforce; (void)lstep; (void)lcount; (void)lcp;
  SoftshellLatticeStats ls;
  uint64_t *lsu = &ls.step; double *lsd[] = {&ls.time, &ls.goal_distance, &ls.step_seconds};
  (void)lsu; (void)lsd;
#endif
}
