// cpp_mesh: the C++ wrapper (include/softshell.hpp) on a mesh: RAII, exceptions, buffers.
//   cpp_mesh [file.obj]     (default data/torus.obj)
#include <cstdio>
#include <exception>

#include "softshell.hpp"

int main(int argc, char **argv) try {
  if (!softshell::header_matches_library()) {
    std::fprintf(stderr, "header %s does not match library %s\n", SOFTSHELL_VERSION_STRING, softshell::version().c_str());
    return 1;
  }
  softshell::Mesh mesh = softshell::Mesh::load_obj(argc > 1 ? argv[1] : "data/torus.obj");
  SoftshellMeshReport r = mesh.report();
  std::printf("%zu vertices, %zu triangles, genus %d, volume %.6g\n", r.vertex_count, r.triangle_count, (int)r.genus,
              r.volume);

  std::vector<float> gauss = mesh.vertex_curvature(SOFTSHELL_CURVATURE_GAUSSIAN);
  double sum = 0.0;
  for (float k : gauss) sum += k;
  std::printf("mean Gaussian curvature %.4g over %zu vertices\n", sum / gauss.size(), gauss.size());

  // Moves transfer ownership; the moved-from handle frees nothing.
  softshell::Mesh moved = std::move(mesh);
  std::vector<float> buffer(3 * moved.vertex_count());
  std::printf("copied %zu floats into a caller's buffer\n", moved.copy_positions(buffer));

  // Errors arrive as exceptions carrying the status and the library's message.
  try {
    softshell::Mesh::from_arrays({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 5});
    std::fprintf(stderr, "an out-of-range index was accepted\n");
    return 1;
  } catch (const softshell::Error &e) {
    std::printf("expected error: %s\n", e.what());
    if (e.status() != SOFTSHELL_STATUS_INVALID_MESH) return 1;
  }
  return 0;
} catch (const std::exception &e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
