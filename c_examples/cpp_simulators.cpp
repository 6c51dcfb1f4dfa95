// cpp_simulators: the three simulators and the CCD queries through the C++ wrapper
// (include/softshell.hpp): a shell contracting under pressure, a gas-filled body falling on the
// ground and cut open by hand (buffers re-read after each topology change), a pinned lattice
// sheet poked in the middle, and one query of each CCD kind.
//   cpp_simulators [file.obj]     (default data/sphere.obj; any closed, outward mesh)
// Writes c_examples/build/cpp_shell.ply, cpp_body.ply and cpp_sheet.obj (one frame each).
// Short on purpose: it runs under valgrind in CI.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <stdexcept>
#include <vector>

#include "softshell.hpp"

namespace {

// The mesh scaled about its centre to a unit bounding-box diagonal: the scale the shell's
// default settings are made for.
softshell::Mesh unit_diagonal(const softshell::Mesh &mesh) {
  SoftshellMeshReport r = mesh.report();
  float centre[3], diagonal = 0.0f;
  for (int k = 0; k < 3; ++k) {
    centre[k] = 0.5f * (r.bbox_min[k] + r.bbox_max[k]);
    diagonal += (r.bbox_max[k] - r.bbox_min[k]) * (r.bbox_max[k] - r.bbox_min[k]);
  }
  diagonal = std::sqrt(diagonal);
  std::vector<float> positions = mesh.positions();
  for (std::size_t i = 0; i < positions.size(); ++i) positions[i] = (positions[i] - centre[i % 3]) / diagonal;
  return softshell::Mesh::from_arrays(positions, mesh.triangles());
}

void shell_contraction(const softshell::Mesh &mesh) {
  SoftshellShellDef def = softshell::shell_def();  // the library's defaults, then edits
  def.stop_volume_ratio = 0.6f;
  softshell::Shell shell(mesh, def);
  // An anisotropic region on the first tenth of the faces (at least one), fibres chosen per face.
  std::vector<std::uint32_t> region;
  const std::size_t region_size = std::max<std::size_t>(1, mesh.triangle_count() / 10);
  for (std::uint32_t f = 0; f < region_size; ++f) region.push_back(f);
  SoftshellAnisotropyDef fibres = softshell::anisotropy_def();
  fibres.target_stretch = 0.9f;
  shell.add_anisotropic_region(region, fibres);

  SoftshellShellStats stats{};
  for (int i = 0; i < 150 && !stats.finished; ++i) stats = shell.step();
  // A frame for MeshLab / Blender / ParaView: curvature, energy and pressure force per vertex.
  shell.save_ply("c_examples/build/cpp_shell.ply", SOFTSHELL_SHELL_PLY_MEAN_CURVATURE);
  std::vector<float> mean = shell.vertex_curvature(SOFTSHELL_CURVATURE_MEAN);
  std::vector<float> energy = shell.face_energy();
  double total = 0.0;
  for (float e : energy) total += e;
  std::printf("shell: %llu steps, V/V0 %.3f%s, membrane energy %.3g J (sum of %zu faces), %zu curvatures, %zu bytes\n",
              (unsigned long long)stats.step, stats.volume_ratio, stats.finished ? " (finished)" : "", total,
              energy.size(), mean.size(), shell.memory_bytes());
}

void body_steps(const softshell::Mesh &mesh) {
  SoftshellBodyDef def = softshell::body_def();
  def.gas_amount = 50.0f;
  def.ground = true;
  def.ground_height = -0.6f;
  softshell::Body body(mesh, def);

  softshell::BodyTopology topology;
  std::vector<float> positions;
  body.refresh(topology);
  for (int i = 0; i < 40; ++i) {
    if (i == 20) {
      // Cut two edges of the first triangle by hand: their shared corner splits, freeing the
      // triangle's corner (held in place by its sides' springs: no crack runs from such a cut).
      body.break_edge(topology.triangles[0], topology.triangles[1]);
      body.break_edge(topology.triangles[1], topology.triangles[2]);
    }
    SoftshellBodyStats stats = body.step();
    if (body.refresh(topology))  // the generation moved: indices and counts changed
      std::printf("body: step %llu, topology generation %llu: %zu vertices, %zu triangles, %zu fragments\n",
                  (unsigned long long)stats.step, (unsigned long long)topology.generation, stats.vertex_count,
                  stats.triangle_count, stats.fragment_count);
    positions.resize(3 * body.vertex_count());  // re-sized every frame: fracture appends vertices
    body.copy_positions(positions);
  }
  body.save_ply("c_examples/build/cpp_body.ply", SOFTSHELL_BODY_PLY_FRAGMENT);
  float lowest = positions[1];
  for (std::size_t i = 1; i < positions.size(); i += 3) lowest = std::fmin(lowest, positions[i]);
  std::printf("body: lowest point y = %.3f (ground at %.3f), %zu bytes\n", lowest, def.ground_height,
              body.memory_bytes());
}

void lattice_poke() {
  SoftshellLatticeDef def = softshell::lattice_def();
  def.columns = 16;
  def.rows = 12;
  def.gravity[1] = 0.0f;
  softshell::Lattice sheet(def);
  for (std::uint32_t r = 0; r < def.rows; ++r) {
    sheet.pin(0, r);
    sheet.pin(def.columns - 1, r);
  }
  std::uint32_t middle = sheet.particle_index(def.columns / 2, def.rows / 2);
  SoftshellLatticeStats stats{};
  for (int i = 0; i < 30; ++i) {
    if (i < 5) sheet.apply_force(def.columns / 2, def.rows / 2, {0.0f, -2.0f, 0.0f});
    stats = sheet.step();
  }
  std::vector<float> positions = sheet.positions();
  sheet.save_obj("c_examples/build/cpp_sheet.obj");
  std::printf("lattice: %zu particles, %zu triangles, middle at y = %.4f, mean goal distance %.2e m\n",
              sheet.particle_count(), sheet.triangle_count(), positions[3 * middle + 1], stats.goal_distance);

  // A single row of particles has no triangles: the copy is an empty vector, not an error.
  def.columns = 5;
  def.rows = 1;
  softshell::Lattice strip(def);
  if (!strip.triangles().empty()) throw std::runtime_error("a one-row lattice has no triangles");
}

void ccd_queries() {
  // A point falling through a still triangle, and two crossing edges.
  softshell::CcdHit vt = softshell::ccd_vertex_triangle({0.2, 1, 0.2}, {0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0.2, -1, 0.2},
                                                        {0, 0, 0}, {1, 0, 0}, {0, 0, 1});
  softshell::CcdHit ee = softshell::ccd_edge_edge({-1, 1, 0}, {1, 1, 0}, {0, 0, -1}, {0, 0, 1}, {-1, -1, 0},
                                                  {1, -1, 0}, {0, 0, -1}, {0, 0, 1});
  std::printf("ccd: vertex-triangle hit %d at t = %.4f, edge-edge hit %d at t = %.4f\n", vt.hit, vt.toi, ee.hit,
              ee.toi);
}

}  // namespace

int main(int argc, char **argv) try {
  softshell::Mesh mesh = unit_diagonal(softshell::Mesh::load_obj(argc > 1 ? argv[1] : "data/sphere.obj"));
  shell_contraction(mesh);
  body_steps(mesh);
  lattice_poke();
  ccd_queries();

  // Settings are checked: a bad def is an exception naming the field.
  try {
    SoftshellShellDef bad = softshell::shell_def();
    bad.poisson_ratio = 0.7f;
    softshell::Shell shell(mesh, bad);
    std::fprintf(stderr, "a Poisson ratio of 0.7 was accepted\n");
    return 1;
  } catch (const softshell::Error &e) {
    std::printf("expected error: %s\n", e.what());
    if (e.status() != SOFTSHELL_STATUS_INVALID_ARGUMENT) return 1;
  }
  return 0;
} catch (const std::exception &e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
