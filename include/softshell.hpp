// softshell.hpp: a thin, header-only C++17 wrapper over the C ABI in softshell.h.
//
// - RAII handles with move semantics (no copies: a handle owns library state).
// - Every failing call throws softshell::Error carrying the status and the library's message.
// - Buffers come out as std::vector, or are copied into a caller's softshell::Span.
// Written by hand (unlike softshell.h); it adds no behaviour of its own.
#ifndef SOFTSHELL_HPP
#define SOFTSHELL_HPP

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

}  // namespace softshell

#endif  // SOFTSHELL_HPP
