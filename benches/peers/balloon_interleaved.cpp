// Peer benchmark, interleaved: the issue-5 balloon (the scene of benches/body_balloon.rs and
// bullet_balloon.cpp) stepped by Bullet's btSoftBody and by softshell's default implicit
// integrator in one process, a few steps of one, then the same steps of the other, and so on.
// Both see the same machine within a fraction of a second, so the ratio of their step times
// keeps little of a shared machine's changing load, which moved the ratio of whole runs taken
// one after the other (balloon_vs_bullet.sh) by up to half between rounds.
//
// Bullet runs on one thread, as it does for its users; softshell on `threads` (default 2). The
// two bodies' working sets (a few MB each) both stay in the shared L3 cache; each block of
// steps starts with the other simulator's data in the cores' own caches, a cost both sides pay
// alike. Which side goes first alternates from block to block.
//
// Build and run: see balloon_vs_bullet.sh (its `interleaved` argument).
//   balloon_interleaved [quick] [block=<steps>] [threads=<n>]
//     quick          200 steps of each instead of 600
//     block=<steps>  steps of one simulator before the other takes its turn (default 10)
//     threads=<n>    softshell's threads (default 2)
// STEP_TIMES=<file> in the environment also writes each step's time of both sides there, a line
// per step ("<step> <Bullet's seconds> <softshell's seconds>"), from which the script takes each
// step's fastest round.
// BLOCK_POSITIONS=1 in the environment also prints each side's mean step time by the step's
// place in its block (the first step of a block starts with the other's data in the caches and,
// for softshell, its worker asleep).
// The last line is machine-readable ("RESULT key=value ...") for the script; nan=1 (and exit
// status 1) when Bullet's nodes became non-finite.

#include "bullet_balloon_scene.hpp"

#include "softshell.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace {

struct Times {
  std::vector<double> seconds;

  double mean_ms() const {
    double total = 0.0;
    for (double t : seconds) total += t;
    return total / static_cast<double>(seconds.size()) * 1e3;
  }

  double median_ms() const {
    std::vector<double> sorted = seconds;
    std::sort(sorted.begin(), sorted.end());
    return sorted[sorted.size() / 2] * 1e3;
  }

  // The mean over the steps [from, to).
  double mean_ms(size_t from, size_t to) const {
    double total = 0.0;
    for (size_t k = from; k < to; ++k) total += seconds[k];
    return total / static_cast<double>(to - from) * 1e3;
  }
};

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  int block = 10;
  unsigned threads = 2;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "quick") == 0) {
      quick = true;
    } else if (std::strncmp(argv[i], "block=", 6) == 0) {
      block = std::atoi(argv[i] + 6);
    } else if (std::strncmp(argv[i], "threads=", 8) == 0) {
      threads = static_cast<unsigned>(std::atoi(argv[i] + 8));
    } else {
      std::fprintf(stderr, "usage: %s [quick] [block=<steps>] [threads=<n>]\n", argv[0]);
      return 2;
    }
  }
  if (block < 1 || threads < 1) {
    std::fprintf(stderr, "block and threads must be at least 1\n");
    return 2;
  }
  const int steps = quick ? 200 : 600;
  const double dt = peer::kTimeStep;
  const double n_rt = peer::kGas;

  std::vector<float> positions;
  std::vector<uint32_t> triangles;
  const double v0 = peer::dropped_balloon(positions, triangles);
  const size_t n = positions.size() / 3;

  peer::BulletBalloon bullet(positions, triangles, false, -1.0f, 5, n_rt);

  // Ours, as body_balloon.rs's default row: K_s from K_s s (s - 1) Σ L0² = 3 nRT with
  // s³ = 1.05 (the analytic V/V0 without gravity; Σ L0² over the edges, the links above).
  const double s = std::cbrt(1.05);
  const double ks = 3.0 * n_rt / (s * (s - 1.0) * bullet.sum_l2);
  SoftshellBodyDef def = softshell_body_def_default();
  def.total_mass = 100.0f;
  def.gas_amount = static_cast<float>(n_rt);
  def.spring_stiffness = static_cast<float>(ks);
  def.spring_damping = 50.0f;
  def.ground = true;
  def.ground_height = 0.0f;
  def.friction = 0.5f;
  def.threads = threads;
  SoftshellMesh* mesh = nullptr;
  SoftshellBody* body = nullptr;
  if (softshell_mesh_from_arrays(positions.data(), n, triangles.data(), triangles.size() / 3, &mesh) !=
          SOFTSHELL_STATUS_OK ||
      softshell_body_new(mesh, &def, &body) != SOFTSHELL_STATUS_OK) {
    std::fprintf(stderr, "softshell: %s\n", softshell_last_error());
    softshell_mesh_free(mesh);
    return 1;
  }
  softshell_mesh_free(mesh);

  std::printf("balloon_interleaved: Bullet %d and softshell %s (%u threads), %zu vertices, %d steps each, "
              "blocks of %d steps\n",
              btGetVersion(), softshell_version_string(), threads, n, steps, block);

  Times bullet_times, our_times;
  bullet_times.seconds.reserve(steps);
  our_times.seconds.reserve(steps);
  std::vector<double> bullet_ratios, our_ratios;
  int failed_at = -1;
  int bullet_nan = -1;  // the first step whose nodes Bullet left non-finite
  auto run_bullet = [&](int from, int to) {
    for (int k = from; k < to; ++k) {
      const auto start = std::chrono::steady_clock::now();
      bullet.world.stepSimulation(btScalar(dt), 0);
      bullet_times.seconds.push_back(
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      const btSoftBody::tNodeArray& nodes = bullet.body->m_nodes;
      if (bullet_nan < 0) {
        for (int i = 0; i < nodes.size(); ++i) {
          const btVector3& p = nodes[i].m_x;
          if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
            bullet_nan = k;
            break;
          }
        }
      }
      if (k >= steps - 100) {
        bullet_ratios.push_back(peer::volume(
                                    [&](uint32_t i) {
                                      const btVector3& p = nodes[static_cast<int>(i)].m_x;
                                      return std::array<double, 3>{p.x(), p.y(), p.z()};
                                    },
                                    triangles) /
                                v0);
      }
    }
  };
  auto run_ours = [&](int from, int to) {
    for (int k = from; k < to && failed_at < 0; ++k) {
      SoftshellBodyStats stats;
      const auto start = std::chrono::steady_clock::now();
      const SoftshellStatus status = softshell_body_step(body, &stats);
      our_times.seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      if (status != SOFTSHELL_STATUS_OK) {
        std::fprintf(stderr, "softshell step %d: %s\n", k, softshell_last_error());
        failed_at = k;
        return;
      }
      if (k >= steps - 100) our_ratios.push_back(stats.volume / v0);
    }
  };
  for (int first = 0, turn = 0; first < steps && failed_at < 0; first += block, ++turn) {
    const int last = std::min(first + block, steps);
    if (turn % 2 == 0) {
      run_bullet(first, last);
      run_ours(first, last);
    } else {
      run_ours(first, last);
      run_bullet(first, last);
    }
  }
  softshell_body_free(body);
  if (failed_at >= 0) return 1;

  auto mean_of = [](const std::vector<double>& v) {
    double total = 0.0;
    for (double x : v) total += x;
    return total / static_cast<double>(v.size());
  };
  const double bullet_mean = bullet_times.mean_ms(), our_mean = our_times.mean_ms();
  const double bullet_median = bullet_times.median_ms(), our_median = our_times.median_ms();
  std::printf("%-28s %9s %9s %9s\n", "", "ms/step", "median", "V/V0");
  std::printf("%-28s %9.3f %9.3f %9.4f\n", "Bullet (1 thread)", bullet_mean, bullet_median, mean_of(bullet_ratios));
  std::printf("%-28s %9.3f %9.3f %9.4f\n", "softshell", our_mean, our_median, mean_of(our_ratios));
  std::printf("softshell / Bullet: %.3f (mean step times), %.3f (median step times)\n", our_mean / bullet_mean,
              our_median / bullet_median);
  // Per stretch of 100 steps (the fall, the impacts, the settling): where the ratio comes from.
  std::printf("per 100 steps, softshell / Bullet (mean step times):");
  for (int from = 0; from < steps; from += 100) {
    const int to = std::min(from + 100, steps);
    std::printf(" %.3f", our_times.mean_ms(from, to) / bullet_times.mean_ms(from, to));
  }
  std::printf("\n");
  if (std::getenv("BLOCK_POSITIONS")) {
    for (int k = 0; k < block; ++k) {
      double o = 0.0, b = 0.0;
      int c = 0;
      for (int i = k; i < steps; i += block, ++c) {
        o += our_times.seconds[i];
        b += bullet_times.seconds[i];
      }
      if (c > 0) std::printf("position %d in block: ours %.3f ms, Bullet %.3f ms\n", k, o / c * 1e3, b / c * 1e3);
    }
  }
  if (const char* path = std::getenv("STEP_TIMES")) {
    FILE* file = std::fopen(path, "w");
    if (file == nullptr) {
      std::fprintf(stderr, "cannot write %s\n", path);
      return 1;
    }
    for (int k = 0; k < steps; ++k) {
      std::fprintf(file, "%d %.9f %.9f\n", k, bullet_times.seconds[k], our_times.seconds[k]);
    }
    std::fclose(file);
  }
  if (bullet_nan >= 0) std::printf("Bullet's nodes are not finite from step %d\n", bullet_nan);
  std::printf("RESULT bullet_ms=%.4f bullet_median=%.4f ours_ms=%.4f ours_median=%.4f ratio=%.4f median_ratio=%.4f "
              "bullet_settled=%.5f ours_settled=%.5f nan=%d\n",
              bullet_mean, bullet_median, our_mean, our_median, our_mean / bullet_mean, our_median / bullet_median,
              mean_of(bullet_ratios), mean_of(our_ratios), bullet_nan < 0 ? 0 : 1);
  return bullet_nan < 0 ? 0 : 1;
}
