// Peer benchmark: the scene of benches/body_balloon.rs run with Bullet's btSoftBody, so that
// softshell's speed can be quoted as a ratio measured in the same session on the same machine.
// Bullet is only a dependency of this program, never of the crate.
//
// Scene (as body_balloon.rs): tests/body_util icosphere(5, 1.0) (10,242 vertices, 20,480
// triangles, same vertex order), radius 1 m, 100 kg, lowest point 1.5 m above the ground at
// y = 0 (the mesh is shifted up by 2.5 m), gravity (0, -9.81, 0) (softshell's default),
// 600 steps of 1/60 s. Bullet settings: kPR = nRT = 2500 J, kLST = 1, piterations = 5,
// kDF = 0.5 (times the ground's friction, set to 1), a btSoftRigidDynamicsWorld with a static
// ground, stepSimulation(1/60, 0): exactly one internal step of 1/60 s per call.
//
// Build and run: see balloon_vs_bullet.sh next to this file.
//   bullet_balloon [quick] [zerog] [margin=<m>] [iterations=<n>]
//     quick         200 steps instead of 600
//     zerog         no gravity and no ground: the zero-gravity row of body_balloon.rs, where the
//                   settled volume measures the links' stiffness against the gas
//     margin=<m>    the soft body's collision margin in m (default: Bullet's own, 0.25 m; the
//                   ball then rests with its nodes about that far above the ground)
//     iterations=n  piterations (default 5)
// The last line is machine-readable ("RESULT key=value ...") for the script.

#include "bullet_balloon_scene.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

using peer::thread_cpu_seconds;
using peer::volume;

int main(int argc, char** argv) {
  bool quick = false;
  bool zero_g = false;
  float margin = -1.0f;  // < 0: keep Bullet's default
  int iterations = 5;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "quick") == 0) {
      quick = true;
    } else if (std::strcmp(argv[i], "zerog") == 0) {
      zero_g = true;
    } else if (std::strncmp(argv[i], "margin=", 7) == 0) {
      margin = std::strtof(argv[i] + 7, nullptr);
    } else if (std::strncmp(argv[i], "iterations=", 11) == 0) {
      iterations = std::atoi(argv[i] + 11);
    } else {
      std::fprintf(stderr, "usage: %s [quick] [zerog] [margin=<m>] [iterations=<n>]\n", argv[0]);
      return 2;
    }
  }
  const int steps = quick ? 200 : 600;
  const double dt = peer::kTimeStep;
  const double n_rt = peer::kGas;

  std::vector<float> positions;
  std::vector<uint32_t> triangles;
  const double v0 = peer::dropped_balloon(positions, triangles);
  const int n = static_cast<int>(positions.size() / 3);

  peer::BulletBalloon scene(positions, triangles, zero_g, margin, iterations, n_rt);
  btSoftRigidDynamicsWorld& world = scene.world;
  btSoftBody* body = scene.body;
  const double sum_l2 = scene.sum_l2;

  std::printf("bullet_balloon: Bullet %d, %d vertices, %zu triangles, %d links, %s, margin %.3f m, %d iterations, %d steps\n",
              btGetVersion(), n, triangles.size() / 3, body->m_links.size(),
              zero_g ? "zero gravity, no ground" : "dropped on the ground", body->getCollisionShape()->getMargin(),
              iterations, steps);

  std::vector<double> times;
  std::vector<double> ratios;
  times.reserve(steps);
  ratios.reserve(steps);
  double cpu = 0.0;
  int first_nan = -1;
  for (int k = 0; k < steps; ++k) {
    const double cpu_start = thread_cpu_seconds();
    const auto start = std::chrono::steady_clock::now();
    // maxSubSteps = 0: one internal step of exactly dt, no interpolation.
    world.stepSimulation(btScalar(dt), 0);
    const auto end = std::chrono::steady_clock::now();
    cpu += thread_cpu_seconds() - cpu_start;
    times.push_back(std::chrono::duration<double>(end - start).count());
    const btSoftBody::tNodeArray& nodes = body->m_nodes;
    if (first_nan < 0) {
      for (int i = 0; i < n; ++i) {
        const btVector3& p = nodes[i].m_x;
        if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
          first_nan = k;
          break;
        }
      }
    }
    const double v = volume(
        [&](uint32_t i) {
          const btVector3& p = nodes[static_cast<int>(i)].m_x;
          return std::array<double, 3>{p.x(), p.y(), p.z()};
        },
        triangles);
    ratios.push_back(v / v0);
  }

  double lowest = INFINITY;
  for (int i = 0; i < n; ++i) lowest = std::min(lowest, double(body->m_nodes[i].m_x.y()));

  std::vector<double> sorted = times;
  std::sort(sorted.begin(), sorted.end());
  auto quantile = [&](double q) { return sorted[static_cast<size_t>(q * sorted.size())] * 1e3; };
  double total = 0.0;
  for (double t : times) total += t;
  const double mean = total / steps * 1e3;
  const size_t tail_start = ratios.size() > 100 ? ratios.size() - 100 : 0;
  double sum = 0.0, low = INFINITY, high = -INFINITY;
  for (size_t i = tail_start; i < ratios.size(); ++i) {
    sum += ratios[i];
    low = std::min(low, ratios[i]);
    high = std::max(high, ratios[i]);
  }
  const double settled = sum / static_cast<double>(ratios.size() - tail_start);
  // Without gravity, the spring constant that would hold this volume in softshell's model with
  // Bullet's pressure (fixed rest areas, so the gas's virtual work at scale s is 3 nRT / s^3
  // against the springs' K (s - 1) Σ L0²): a rough figure for how soft the PBD links end up.
  const double s = std::cbrt(settled);
  const double k_implied = 3.0 * n_rt / (s * s * s * (s - 1.0) * sum_l2);

  std::printf("ms/step %.3f (10th pct. %.3f, median %.3f; CPU %.3f)\n", mean, quantile(0.1), quantile(0.5),
              cpu / steps * 1e3);
  std::printf("V/V0 over the last %zu steps: mean %.4f, min %.4f, max %.4f; lowest node y %.4f m\n",
              ratios.size() - tail_start, settled, low, high, lowest);
  std::printf("NaN: %s\n", first_nan < 0 ? "none" : ("from step " + std::to_string(first_nan)).c_str());
  if (zero_g) {
    std::printf("implied spring constant: %.1f N/m (sum L0^2 = %.3f m^2)\n", k_implied, sum_l2);
  }
  std::printf("RESULT ms=%.4f p10=%.4f median=%.4f cpu=%.4f settled=%.5f min=%.5f max=%.5f nan=%d\n", mean,
              quantile(0.1), quantile(0.5), cpu / steps * 1e3, settled, low, high, first_nan < 0 ? 0 : 1);

  return first_nan < 0 ? 0 : 1;
}
