// softshell.hpp: a thin, header-only C++17 wrapper over the C ABI in softshell.h.
//
// - RAII handles with move semantics (no copies: a handle owns library state).
// - Every failing call throws softshell::Error carrying the status and the library's message.
// - Buffers come out as std::vector, or are copied into a caller's softshell::Span.
// - Defs are the C structs: start from shell_def(), body_def(), ... (the library's defaults)
//   and edit fields; stats are the C structs too.
// Handles: Mesh, Shell, Body, Lattice; free functions: ccd_vertex_triangle, ccd_edge_edge.
// Written by hand (unlike softshell.h); it adds no behaviour of its own.
#ifndef SOFTSHELL_HPP
#define SOFTSHELL_HPP

#include <array>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "softshell.h"

namespace softshell {

/// A failed call: the status code and the message of softshell_last_error().
class Error : public std::runtime_error {
 public:
  Error(SoftshellStatus status, const std::string &message)
      : std::runtime_error(std::string(softshell_status_name(status)) + ": " + message), status_(status) {}
  SoftshellStatus status() const noexcept { return status_; }
  const char *status_name() const noexcept { return softshell_status_name(status_); }

 private:
  SoftshellStatus status_;
};

/// x, y, z (m) for obstacles, impulses, forces and directions.
using Vec3 = std::array<float, 3>;
/// x, y, z in double precision for the CCD queries.
using Vec3d = std::array<double, 3>;

/// Throws softshell::Error unless `status` is SOFTSHELL_STATUS_OK.
inline void check(SoftshellStatus status) {
  if (status != SOFTSHELL_STATUS_OK) throw Error(status, softshell_last_error());
}

/// A non-owning view of a contiguous buffer (std::span is C++20).
template <class T>
class Span {
 public:
  Span(T *data, std::size_t size) noexcept : data_(data), size_(size) {}
  Span(std::vector<T> &v) noexcept : data_(v.data()), size_(v.size()) {}  // NOLINT: implicit by design
  template <class U, std::size_t N>
  Span(std::array<U, N> &a) noexcept : data_(a.data()), size_(N) {}  // NOLINT: implicit by design
  template <class U>
  Span(const std::vector<U> &v) noexcept : data_(v.data()), size_(v.size()) {}  // NOLINT: read-only views
  T *data() const noexcept { return data_; }
  std::size_t size() const noexcept { return size_; }
  T *begin() const noexcept { return data_; }
  T *end() const noexcept { return data_ + size_; }
  T &operator[](std::size_t i) const noexcept { return data_[i]; }

 private:
  T *data_;
  std::size_t size_;
};

namespace detail {

/// Runs a `(out, capacity, out_len)` copy twice: once to size, once to fill.
template <class T, class Copy>
std::vector<T> copy_all(Copy &&copy) {
  std::size_t needed = 0;
  SoftshellStatus status = copy(static_cast<T *>(nullptr), std::size_t{0}, &needed);
  if (status != SOFTSHELL_STATUS_BUFFER_TOO_SMALL) check(status);
  // Nothing to copy (a lattice with no triangles): a NULL buffer would be refused as too small.
  if (needed == 0) return {};
  std::vector<T> out(needed);
  check(copy(out.data(), out.size(), &needed));
  out.resize(needed);
  return out;
}

/// Copies into a caller's span; returns the number of elements written.
template <class T, class Copy>
std::size_t copy_into(Span<T> out, Copy &&copy) {
  std::size_t written = 0;
  check(copy(out.data(), out.size(), &written));
  return written;
}

/// `copy_all` for a C copy function `f(handle, out, capacity, out_len)`.
template <class T, class H>
std::vector<T> copy_all(SoftshellStatus (*f)(const H *, T *, std::size_t, std::size_t *), const H *handle) {
  return copy_all<T>([&](T *o, std::size_t c, std::size_t *n) { return f(handle, o, c, n); });
}

/// `copy_into` for a C copy function `f(handle, out, capacity, out_len)`.
template <class T, class H>
std::size_t copy_into(Span<T> out, SoftshellStatus (*f)(const H *, T *, std::size_t, std::size_t *), const H *handle) {
  return copy_into(out, [&](T *o, std::size_t c, std::size_t *n) { return f(handle, o, c, n); });
}

/// Owns one handle and frees it with `Free`; movable, not copyable.
template <class H, void (*Free)(H *)>
class Unique {
 public:
  Unique() noexcept = default;
  explicit Unique(H *handle) noexcept : handle_(handle) {}
  Unique(Unique &&other) noexcept : handle_(std::exchange(other.handle_, nullptr)) {}
  Unique &operator=(Unique &&other) noexcept {
    if (this != &other) {
      Free(handle_);
      handle_ = std::exchange(other.handle_, nullptr);
    }
    return *this;
  }
  Unique(const Unique &) = delete;
  Unique &operator=(const Unique &) = delete;
  ~Unique() { Free(handle_); }
  H *get() const noexcept { return handle_; }
  explicit operator bool() const noexcept { return handle_ != nullptr; }

 private:
  H *handle_ = nullptr;
};

}  // namespace detail

/// Version of the linked library ("major.minor.patch").
inline std::string version() { return softshell_version_string(); }

/// True when the linked library is the one this header was generated with.
inline bool header_matches_library() noexcept { return softshell_abi_version() == SOFTSHELL_ABI_VERSION; }

/// An immutable triangle mesh (see SoftshellMesh in softshell.h).
class Mesh {
 public:
  /// `positions`: x,y,z per vertex; `triangles`: a,b,c per triangle, counter-clockwise from outside.
  static Mesh from_arrays(const float *positions, std::size_t vertex_count, const std::uint32_t *triangles,
                          std::size_t triangle_count) {
    SoftshellMesh *mesh = nullptr;
    check(softshell_mesh_from_arrays(positions, vertex_count, triangles, triangle_count, &mesh));
    return Mesh(mesh);
  }
  static Mesh from_arrays(const std::vector<float> &positions, const std::vector<std::uint32_t> &triangles) {
    return from_arrays(positions.data(), positions.size() / 3, triangles.data(), triangles.size() / 3);
  }
  static Mesh load_obj(const std::string &path) {
    SoftshellMesh *mesh = nullptr;
    check(softshell_mesh_load_obj(path.c_str(), &mesh));
    return Mesh(mesh);
  }
  void save_obj(const std::string &path) const { check(softshell_mesh_save_obj(get(), path.c_str())); }
  /// PLY with curvature scalars; `colour_by`: SOFTSHELL_CURVATURE_MEAN or _GAUSSIAN.
  void save_ply(const std::string &path, std::uint32_t colour_by = SOFTSHELL_CURVATURE_MEAN) const {
    check(softshell_mesh_save_ply(get(), path.c_str(), colour_by));
  }

  std::size_t vertex_count() const noexcept { return softshell_mesh_vertex_count(get()); }
  std::size_t triangle_count() const noexcept { return softshell_mesh_triangle_count(get()); }
  SoftshellMeshReport report() const {
    SoftshellMeshReport r;
    check(softshell_mesh_report(get(), &r));
    return r;
  }
  std::vector<float> positions() const {
    return detail::copy_all<float>([&](float *o, std::size_t c, std::size_t *n) { return softshell_mesh_copy_positions(get(), o, c, n); });
  }
  std::size_t copy_positions(Span<float> out) const {
    return detail::copy_into(out, [&](float *o, std::size_t c, std::size_t *n) { return softshell_mesh_copy_positions(get(), o, c, n); });
  }
  std::vector<std::uint32_t> triangles() const {
    return detail::copy_all<std::uint32_t>(
        [&](std::uint32_t *o, std::size_t c, std::size_t *n) { return softshell_mesh_copy_triangles(get(), o, c, n); });
  }
  /// `kind`: SOFTSHELL_CURVATURE_MEAN or SOFTSHELL_CURVATURE_GAUSSIAN.
  std::vector<float> vertex_curvature(std::uint32_t kind) const {
    return detail::copy_all<float>(
        [&](float *o, std::size_t c, std::size_t *n) { return softshell_mesh_copy_vertex_curvature(get(), kind, o, c, n); });
  }

  const SoftshellMesh *get() const noexcept { return handle_.get(); }

 private:
  explicit Mesh(SoftshellMesh *mesh) noexcept : handle_(mesh) {}
  detail::Unique<SoftshellMesh, softshell_mesh_free> handle_;
};

// ---------------------------------------------------------------------------------------------
// Defs with the library's defaults (edit fields, then pass them to a constructor).

/// SoftshellShellDef filled by softshell_shell_def_default().
inline SoftshellShellDef shell_def() noexcept { return softshell_shell_def_default(); }
/// SoftshellAnisotropyDef filled by softshell_anisotropy_def_default().
inline SoftshellAnisotropyDef anisotropy_def() noexcept { return softshell_anisotropy_def_default(); }
/// SoftshellBodyDef filled by softshell_body_def_default().
inline SoftshellBodyDef body_def() noexcept { return softshell_body_def_default(); }
/// SoftshellLatticeDef filled by softshell_lattice_def_default().
inline SoftshellLatticeDef lattice_def() noexcept { return softshell_lattice_def_default(); }

/// A thin shell squeezed by outside pressure (see SoftshellShell in softshell.h).
class Shell {
 public:
  /// Copies `mesh` (closed, oriented); the mesh may be destroyed afterwards.
  explicit Shell(const Mesh &mesh, const SoftshellShellDef &def = shell_def()) {
    SoftshellShell *shell = nullptr;
    check(softshell_shell_new(mesh.get(), &def, &shell));
    handle_ = detail::Unique<SoftshellShell, softshell_shell_free>(shell);
  }

  /// Makes `faces` (triangle indices, distinct) an anisotropic region (SPEC 1.5).
  void add_anisotropic_region(Span<const std::uint32_t> faces, const SoftshellAnisotropyDef &def = anisotropy_def()) {
    check(softshell_shell_add_anisotropic_region(get(), faces.data(), faces.size(), &def));
  }
  void add_anisotropic_region(const std::vector<std::uint32_t> &faces,
                              const SoftshellAnisotropyDef &def = anisotropy_def()) {
    add_anisotropic_region(Span<const std::uint32_t>(faces.data(), faces.size()), def);
  }

  /// One time step; returns its stats (energies and residual cost one extra pass).
  SoftshellShellStats step() {
    SoftshellShellStats stats;
    check(softshell_shell_step(get(), &stats));
    return stats;
  }
  /// One time step without stats (no extra pass). Throws softshell::Error (UNSTABLE) on divergence.
  void advance() { check(softshell_shell_step(get(), nullptr)); }

  std::size_t vertex_count() const noexcept { return softshell_shell_vertex_count(get()); }
  std::size_t memory_bytes() const noexcept { return softshell_shell_memory_bytes(get()); }
  /// x,y,z per vertex, m.
  std::vector<float> positions() const { return detail::copy_all<float>(softshell_shell_copy_positions, get()); }
  std::size_t copy_positions(Span<float> out) const {
    return detail::copy_into(out, softshell_shell_copy_positions, get());
  }
  /// Membrane energy per triangle, J.
  std::vector<float> face_energy() const { return detail::copy_all<float>(softshell_shell_copy_face_energy, get()); }
  /// `kind`: SOFTSHELL_CURVATURE_MEAN or SOFTSHELL_CURVATURE_GAUSSIAN; one value per vertex.
  std::vector<float> vertex_curvature(std::uint32_t kind) const {
    return detail::copy_all<float>(
        [&](float *o, std::size_t c, std::size_t *n) { return softshell_shell_copy_vertex_curvature(get(), kind, o, c, n); });
  }
  /// PLY with mean_curvature, gaussian_curvature, energy and pressure_force per vertex, coloured
  /// by `colour_by` (SOFTSHELL_SHELL_PLY_MEAN_CURVATURE, _GAUSSIAN_CURVATURE, _ENERGY, _PRESSURE_FORCE).
  void save_ply(const std::string &path, std::uint32_t colour_by = SOFTSHELL_SHELL_PLY_MEAN_CURVATURE) const {
    check(softshell_shell_save_ply(get(), path.c_str(), colour_by));
  }
  /// One OBJ frame of the current shape.
  void save_obj(const std::string &path) const { check(softshell_shell_save_obj(get(), path.c_str())); }

  SoftshellShell *get() const noexcept { return handle_.get(); }

 private:
  detail::Unique<SoftshellShell, softshell_shell_free> handle_;
};

/// What a body's connectivity is at one topology generation: re-read by Body::refresh only when
/// the generation changed (fracture appends vertices and rewrites triangles).
struct BodyTopology {
  std::uint64_t generation = ~std::uint64_t{0};  // no generation read yet
  std::vector<std::uint32_t> triangles;          // a,b,c per triangle
  std::vector<std::uint32_t> vertex_origins;     // input-mesh vertex of each vertex
  std::vector<std::uint32_t> fragment_ids;       // connected piece of each triangle
};

/// A mass-spring soft body with gas and fracture (see SoftshellBody in softshell.h).
class Body {
 public:
  /// Copies `mesh`; the mesh may be destroyed afterwards.
  explicit Body(const Mesh &mesh, const SoftshellBodyDef &def = body_def()) {
    SoftshellBody *body = nullptr;
    check(softshell_body_new(mesh.get(), &def, &body));
    handle_ = detail::Unique<SoftshellBody, softshell_body_free>(body);
  }

  void add_sphere_obstacle(const Vec3 &center, float radius) {
    check(softshell_body_add_sphere_obstacle(get(), center.data(), radius));
  }
  /// Half-space on the side `normal` points to.
  void add_plane_obstacle(const Vec3 &point, const Vec3 &normal) {
    check(softshell_body_add_plane_obstacle(get(), point.data(), normal.data()));
  }
  void pin_vertex(std::uint32_t vertex) { check(softshell_body_pin_vertex(get(), vertex)); }
  /// N s.
  void apply_impulse(std::uint32_t vertex, const Vec3 &impulse) {
    check(softshell_body_apply_impulse(get(), vertex, impulse.data()));
  }
  /// Cuts the spring a-b by hand (bumps the topology generation).
  void break_edge(std::uint32_t a, std::uint32_t b) { check(softshell_body_break_edge(get(), a, b)); }
  /// Cuts the springs of all `pairs` (vertex a, vertex b) by hand in one topology change, all or
  /// none (a refused pair throws and changes nothing); returns the springs broken.
  std::size_t break_edges(const std::vector<std::array<std::uint32_t, 2>> &pairs) {
    static_assert(sizeof(std::array<std::uint32_t, 2>) == 2 * sizeof(std::uint32_t), "pairs are read as one array");
    std::size_t broken = 0;
    check(softshell_body_break_edges(get(), pairs.empty() ? nullptr : pairs.front().data(), pairs.size(), &broken));
    return broken;
  }

  SoftshellBodyStats step() {
    SoftshellBodyStats stats;
    check(softshell_body_step(get(), &stats));
    return stats;
  }

  std::uint64_t topology_generation() const noexcept { return softshell_body_topology_generation(get()); }
  std::size_t vertex_count() const noexcept { return softshell_body_vertex_count(get()); }
  std::size_t triangle_count() const noexcept { return softshell_body_triangle_count(get()); }
  std::size_t fragment_count() const noexcept { return softshell_body_fragment_count(get()); }
  std::size_t memory_bytes() const noexcept { return softshell_body_memory_bytes(get()); }

  std::vector<float> positions() const { return detail::copy_all<float>(softshell_body_copy_positions, get()); }
  std::size_t copy_positions(Span<float> out) const {
    return detail::copy_into(out, softshell_body_copy_positions, get());
  }
  std::vector<float> velocities() const { return detail::copy_all<float>(softshell_body_copy_velocities, get()); }
  std::vector<float> masses() const { return detail::copy_all<float>(softshell_body_copy_masses, get()); }
  std::vector<std::uint32_t> triangles() const {
    return detail::copy_all<std::uint32_t>(softshell_body_copy_triangles, get());
  }
  std::vector<std::uint32_t> vertex_origins() const {
    return detail::copy_all<std::uint32_t>(softshell_body_copy_vertex_origins, get());
  }
  std::vector<std::uint32_t> fragment_ids() const {
    return detail::copy_all<std::uint32_t>(softshell_body_copy_fragment_ids, get());
  }

  /// Re-reads `topology` if the body's topology generation moved on since it was read (or it
  /// was never read); returns true when it did. Call it after every step, break_edge or
  /// impulse before using indices; positions() always has vertex_count() vertices.
  bool refresh(BodyTopology &topology) const {
    std::uint64_t generation = topology_generation();
    if (generation == topology.generation) return false;
    topology.triangles = triangles();
    topology.vertex_origins = vertex_origins();
    topology.fragment_ids = fragment_ids();
    topology.generation = generation;
    return true;
  }
  /// PLY with speed, fragment_shade, mean_curvature and fragment per vertex, coloured by
  /// `colour_by` (SOFTSHELL_BODY_PLY_SPEED, _FRAGMENT, _MEAN_CURVATURE).
  void save_ply(const std::string &path, std::uint32_t colour_by = SOFTSHELL_BODY_PLY_SPEED) const {
    check(softshell_body_save_ply(get(), path.c_str(), colour_by));
  }
  /// One OBJ frame of every piece.
  void save_obj(const std::string &path) const { check(softshell_body_save_obj(get(), path.c_str())); }

  SoftshellBody *get() const noexcept { return handle_.get(); }

 private:
  detail::Unique<SoftshellBody, softshell_body_free> handle_;
};

/// A FastLSM elastic lattice surface (see SoftshellLattice in softshell.h).
class Lattice {
 public:
  /// A full sheet of def.columns x def.rows particles.
  explicit Lattice(const SoftshellLatticeDef &def = lattice_def()) { create(def, nullptr); }
  /// `mask`: rows*columns bytes, row-major, 1 = particle, 0 = hole.
  Lattice(const SoftshellLatticeDef &def, const std::vector<std::uint8_t> &mask) {
    std::size_t sites = static_cast<std::size_t>(def.columns) * def.rows;
    if (mask.size() != sites)
      throw Error(SOFTSHELL_STATUS_INVALID_ARGUMENT, "mask has " + std::to_string(mask.size()) + " entries, columns * rows = " +
                                                         std::to_string(sites));
    create(def, mask.data());
  }

  void pin(std::uint32_t column, std::uint32_t row) { check(softshell_lattice_pin(get(), column, row)); }
  void unpin(std::uint32_t column, std::uint32_t row) { check(softshell_lattice_unpin(get(), column, row)); }
  /// N, for the next step only.
  void apply_force(std::uint32_t column, std::uint32_t row, const Vec3 &force) {
    check(softshell_lattice_apply_force(get(), column, row, force.data()));
  }
  /// x,y,z per particle (3 * particle_count() floats).
  void set_positions(Span<const float> positions) {
    check(softshell_lattice_set_positions(get(), positions.data(), positions.size()));
  }
  SoftshellLatticeStats step() {
    SoftshellLatticeStats stats;
    check(softshell_lattice_step(get(), &stats));
    return stats;
  }

  std::size_t particle_count() const noexcept { return softshell_lattice_particle_count(get()); }
  std::size_t triangle_count() const noexcept { return softshell_lattice_triangle_count(get()); }
  std::size_t memory_bytes() const noexcept { return softshell_lattice_memory_bytes(get()); }
  /// Index of the particle at (column, row) into positions and triangles.
  std::uint32_t particle_index(std::uint32_t column, std::uint32_t row) const {
    std::uint32_t index = 0;
    check(softshell_lattice_particle_index(get(), column, row, &index));
    return index;
  }
  std::vector<float> positions() const { return detail::copy_all<float>(softshell_lattice_copy_positions, get()); }
  std::size_t copy_positions(Span<float> out) const {
    return detail::copy_into(out, softshell_lattice_copy_positions, get());
  }
  std::vector<float> velocities() const { return detail::copy_all<float>(softshell_lattice_copy_velocities, get()); }
  std::vector<float> goals() const { return detail::copy_all<float>(softshell_lattice_copy_goals, get()); }
  std::vector<std::uint32_t> triangles() const {
    return detail::copy_all<std::uint32_t>(softshell_lattice_copy_triangles, get());
  }
  /// PLY with height, speed and goal_distance per particle, coloured by `colour_by`
  /// (SOFTSHELL_LATTICE_PLY_HEIGHT, _SPEED, _GOAL_DISTANCE).
  void save_ply(const std::string &path, std::uint32_t colour_by = SOFTSHELL_LATTICE_PLY_HEIGHT) const {
    check(softshell_lattice_save_ply(get(), path.c_str(), colour_by));
  }
  /// One OBJ frame of the sheet.
  void save_obj(const std::string &path) const { check(softshell_lattice_save_obj(get(), path.c_str())); }

  SoftshellLattice *get() const noexcept { return handle_.get(); }

 private:
  void create(const SoftshellLatticeDef &def, const std::uint8_t *mask) {
    SoftshellLattice *lattice = nullptr;
    check(softshell_lattice_new(&def, mask, &lattice));
    handle_ = detail::Unique<SoftshellLattice, softshell_lattice_free>(lattice);
  }
  detail::Unique<SoftshellLattice, softshell_lattice_free> handle_;
};

/// Result of a continuous collision query: `hit` and the earliest time of contact in [0, 1]
/// (1 when there is none).
struct CcdHit {
  bool hit;
  double toi;
};

/// Vertex p against triangle abc, each moving linearly from its first to its second position.
inline CcdHit ccd_vertex_triangle(const Vec3d &p0, const Vec3d &a0, const Vec3d &b0, const Vec3d &c0, const Vec3d &p1,
                                  const Vec3d &a1, const Vec3d &b1, const Vec3d &c1, double thickness = 0.0) {
  std::int32_t hit = 0;
  double toi = 1.0;
  check(softshell_ccd_vertex_triangle(p0.data(), a0.data(), b0.data(), c0.data(), p1.data(), a1.data(), b1.data(),
                                      c1.data(), thickness, &hit, &toi));
  return CcdHit{hit != 0, toi};
}

/// Edge ab against edge cd, each point moving linearly from its first to its second position.
inline CcdHit ccd_edge_edge(const Vec3d &a0, const Vec3d &b0, const Vec3d &c0, const Vec3d &d0, const Vec3d &a1,
                            const Vec3d &b1, const Vec3d &c1, const Vec3d &d1, double thickness = 0.0) {
  std::int32_t hit = 0;
  double toi = 1.0;
  check(softshell_ccd_edge_edge(a0.data(), b0.data(), c0.data(), d0.data(), a1.data(), b1.data(), c1.data(), d1.data(),
                                thickness, &hit, &toi));
  return CcdHit{hit != 0, toi};
}

}  // namespace softshell

#endif  // SOFTSHELL_HPP
