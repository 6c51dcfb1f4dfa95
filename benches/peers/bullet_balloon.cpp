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

#include <btBulletDynamicsCommon.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace {

// A port of tests/body_util/mod.rs `icosphere`: the same base icosahedron, the same face
// split order and the same midpoint numbering (a midpoint gets the next index the first time
// its edge is met), so vertex i here is vertex i there. Midpoints are made in double and the
// unit-sphere projection is rounded to float before the radius is applied, as there.
void icosphere(unsigned levels, float radius, std::vector<float>& positions, std::vector<uint32_t>& triangles) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<std::array<double, 3>> p = {
      {-1.0, t, 0.0}, {1.0, t, 0.0}, {-1.0, -t, 0.0}, {1.0, -t, 0.0},
      {0.0, -1.0, t}, {0.0, 1.0, t}, {0.0, -1.0, -t}, {0.0, 1.0, -t},
      {t, 0.0, -1.0}, {t, 0.0, 1.0}, {-t, 0.0, -1.0}, {-t, 0.0, 1.0},
  };
  std::vector<std::array<uint32_t, 3>> f = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1},
  };
  for (unsigned level = 0; level < levels; ++level) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    std::vector<std::array<uint32_t, 3>> next;
    next.reserve(f.size() * 4);
    for (const auto& tri : f) {
      uint32_t m[3];
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[k], b = tri[(k + 1) % 3];
        const auto key = std::make_pair(std::min(a, b), std::max(a, b));
        auto found = mid.find(key);
        if (found == mid.end()) {
          const auto pa = p[a], pb = p[b];
          p.push_back({(pa[0] + pb[0]) / 2.0, (pa[1] + pb[1]) / 2.0, (pa[2] + pb[2]) / 2.0});
          found = mid.emplace(key, static_cast<uint32_t>(p.size() - 1)).first;
        }
        m[k] = found->second;
      }
      next.push_back({tri[0], m[0], m[2]});
      next.push_back({tri[1], m[1], m[0]});
      next.push_back({tri[2], m[2], m[1]});
      next.push_back({m[0], m[1], m[2]});
    }
    f = std::move(next);
  }
  positions.clear();
  for (const auto& q : p) {
    const double l = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    for (int c = 0; c < 3; ++c) positions.push_back(static_cast<float>(q[c] / l) * radius);
  }
  triangles.clear();
  for (const auto& tri : f) triangles.insert(triangles.end(), tri.begin(), tri.end());
}

// Enclosed volume in double from float coordinates, the formula of body_balloon.rs
// `volume_factor` (times 4/3 pi): the same measure on both sides of the comparison.
template <class Position>
double volume(const Position& position, const std::vector<uint32_t>& triangles) {
  double v = 0.0;
  for (size_t i = 0; i < triangles.size(); i += 3) {
    const std::array<double, 3> a = position(triangles[i]), b = position(triangles[i + 1]),
                                c = position(triangles[i + 2]);
    v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
         a[2] * (b[0] * c[1] - b[1] * c[0]);
  }
  return v / 6.0;
}

double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

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
  const double dt = 1.0 / 60.0;
  const double n_rt = 2500.0;

  std::vector<float> positions;
  std::vector<uint32_t> triangles;
  icosphere(5, 1.0f, positions, triangles);
  const int n = static_cast<int>(positions.size() / 3);
  // Dropped from 1.5 m as in body_balloon.rs: the same float addition to every y.
  for (int i = 0; i < n; ++i) positions[3 * i + 1] += 2.5f;
  const double v0 = volume(
      [&](uint32_t i) {
        return std::array<double, 3>{positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
      },
      triangles);

  // Each edge once, in the order of first appearance walking the triangles' edges (j, k) =
  // (2, 0), (0, 1), (1, 2), the order btSoftBodyHelpers::CreateFromTriMesh appends links in;
  // built here with a map instead of its n x n table (10,242^2 flags). Σ L0² is kept for the
  // stiffness estimate printed at the end.
  std::vector<std::pair<int, int>> edges;
  double sum_l2 = 0.0;
  {
    std::set<std::pair<uint32_t, uint32_t>> seen;
    for (size_t t = 0; t < triangles.size(); t += 3) {
      for (int j = 2, k = 0; k < 3; j = k++) {
        const uint32_t a = triangles[t + j], b = triangles[t + k];
        if (seen.emplace(std::min(a, b), std::max(a, b)).second) {
          edges.emplace_back(static_cast<int>(a), static_cast<int>(b));
          double l2 = 0.0;
          for (int c = 0; c < 3; ++c) {
            const double d = double(positions[3 * a + c]) - double(positions[3 * b + c]);
            l2 += d * d;
          }
          sum_l2 += l2;
        }
      }
    }
  }

  // World: the usual soft-rigid set-up; btSoftRigidDynamicsWorld makes its default (CPU,
  // single-threaded) soft body solver when given none.
  btSoftBodyRigidBodyCollisionConfiguration collision_configuration;
  btCollisionDispatcher dispatcher(&collision_configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btSoftRigidDynamicsWorld world(&dispatcher, &broadphase, &solver, &collision_configuration);
  const btVector3 gravity(0, zero_g ? 0 : btScalar(-9.81), 0);
  world.setGravity(gravity);
  // Soft bodies take gravity from the world info, whose own default is (0, -10, 0).
  btSoftBodyWorldInfo& info = world.getWorldInfo();
  info.m_gravity = gravity;

  // Ground: the top face of a large static box at y = 0. Not a btStaticPlaneShape: soft-rigid
  // contacts go through btSparseSdf, whose distance is 0 everywhere for a non-convex shape
  // (btSparseSDF.h, DistanceToShape), so a plane would not work as a ground for a soft body.
  btBoxShape ground_shape(btVector3(50, 50, 50));
  btTransform ground_pose;
  ground_pose.setIdentity();
  ground_pose.setOrigin(btVector3(0, -50, 0));
  btDefaultMotionState ground_motion(ground_pose);
  btRigidBody ground(btRigidBody::btRigidBodyConstructionInfo(0, &ground_motion, &ground_shape));
  // The contact's friction coefficient is kDF times this (btSoftBodyInternals.h, CollideSDF_RS),
  // so 1 here makes it kDF = 0.5, softshell's Coulomb friction 0.5.
  ground.setFriction(1);
  if (!zero_g) world.addRigidBody(&ground);

  std::vector<btVector3> x(n);
  for (int i = 0; i < n; ++i) x[i] = btVector3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
  // Unit masses here; setTotalMass(.., true) below spreads the mass by adjacent face area, as
  // softshell does (m_i proportional to the sum of the areas of the triangles at i).
  auto* body = new btSoftBody(&info, n, x.data(), nullptr);
  for (const auto& e : edges) body->appendLink(e.first, e.second);
  for (size_t t = 0; t < triangles.size(); t += 3) {
    body->appendFace(static_cast<int>(triangles[t]), static_cast<int>(triangles[t + 1]),
                     static_cast<int>(triangles[t + 2]));
  }
  // CreateFromTriMesh shuffles links and faces by default (a fixed seed); do the same, so the
  // Gauss-Seidel order of the links is the one a user of the helper gets.
  body->randomizeConstraints();
  body->m_materials[0]->m_kLST = 1;
  body->m_cfg.piterations = iterations;
  // Pressure: applyForces adds kPR / |V| * A_i * n_i to node i (n_i its unit normal, A_i the
  // mean of twice the adjacent triangles' areas, which is the lumped area Σ A_f / 3 where 6
  // triangles meet): an ideal gas with nRT = kPR, except that A_i is the area at rest
  // (updateArea only runs in updateConstants, before the first step), so an inflated ball's gas
  // pushes on its rest area, (A0 / A) times the force of softshell's gas.
  body->m_cfg.kPR = btScalar(n_rt);
  body->m_cfg.kDF = btScalar(0.5);
  if (margin >= 0) body->getCollisionShape()->setMargin(margin);
  body->setTotalMass(100, true);
  // The timing must cover the simulation the whole time; no sleeping.
  body->setActivationState(DISABLE_DEACTIVATION);
  world.addSoftBody(body);

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

  world.removeSoftBody(body);
  delete body;
  if (!zero_g) world.removeRigidBody(&ground);
  return first_nan < 0 ? 0 : 1;
}
