// The issue-5 balloon in Bullet's btSoftBody, shared by bullet_balloon.cpp (Bullet alone, run
// by balloon_vs_bullet.sh next to it) and balloon_interleaved.cpp (Bullet and softshell stepped
// in turn in one process). Bullet is only a dependency of these programs, never of the crate.
// The scene and its settings are described at the top of bullet_balloon.cpp.
#pragma once

#include <btBulletDynamicsCommon.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <map>
#include <memory>
#include <set>
#include <utility>
#include <vector>

namespace peer {

// A port of tests/body_util/mod.rs `icosphere`: the same base icosahedron, the same face
// split order and the same midpoint numbering (a midpoint gets the next index the first time
// its edge is met), so vertex i here is vertex i there. Midpoints are made in double and the
// unit-sphere projection is rounded to float before the radius is applied, as there.
inline void icosphere(unsigned levels, float radius, std::vector<float>& positions, std::vector<uint32_t>& triangles) {
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

inline double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// The time step and the gas nRT of the scene (body_balloon.rs's).
constexpr double kTimeStep = 1.0 / 60.0;
constexpr double kGas = 2500.0;

// The scene's mesh as body_balloon.rs makes it: icosphere(5, 1) (10,242 vertices) dropped from
// 1.5 m (its lowest point; the same float addition to every y). Returns its volume V0.
inline double dropped_balloon(std::vector<float>& positions, std::vector<uint32_t>& triangles) {
  icosphere(5, 1.0f, positions, triangles);
  for (size_t i = 0; i < positions.size() / 3; ++i) positions[3 * i + 1] += 2.5f;
  return volume(
      [&](uint32_t i) {
        return std::array<double, 3>{positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
      },
      triangles);
}

// The soft body and its world: a static ground (unless `zero_g`), the balloon made from
// `positions` (already placed) and `triangles` with gas nRT = `n_rt`, the soft body's collision
// margin `margin` (< 0: Bullet's own) and `iterations` position iterations.
struct BulletBalloon {
  BulletBalloon(const std::vector<float>& positions, const std::vector<uint32_t>& triangles, bool zero_g,
                float margin, int iterations, double n_rt)
      : zero_g(zero_g) {
    const int n = static_cast<int>(positions.size() / 3);
    // Each edge once, in the order of first appearance walking the triangles' edges (j, k) =
    // (2, 0), (0, 1), (1, 2), the order btSoftBodyHelpers::CreateFromTriMesh appends links in;
    // built here with a map instead of its n x n table (10,242^2 flags). Σ L0² is kept (the
    // stiffness bullet_balloon estimates, softshell's K_s in balloon_interleaved).
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
    const btVector3 gravity(0, zero_g ? 0 : btScalar(-9.81), 0);
    world.setGravity(gravity);
    // Soft bodies take gravity from the world info, whose own default is (0, -10, 0).
    btSoftBodyWorldInfo& info = world.getWorldInfo();
    info.m_gravity = gravity;

    // Ground: the top face of a large static box at y = 0. Not a btStaticPlaneShape: soft-rigid
    // contacts go through btSparseSdf, whose distance is 0 everywhere for a non-convex shape
    // (btSparseSDF.h, DistanceToShape), so a plane would not work as a ground for a soft body.
    btTransform ground_pose;
    ground_pose.setIdentity();
    ground_pose.setOrigin(btVector3(0, -50, 0));
    ground_motion.setWorldTransform(ground_pose);
    ground = std::make_unique<btRigidBody>(btRigidBody::btRigidBodyConstructionInfo(0, &ground_motion, &ground_shape));
    // The contact's friction coefficient is kDF times this (btSoftBodyInternals.h, CollideSDF_RS),
    // so 1 here makes it kDF = 0.5, softshell's Coulomb friction 0.5.
    ground->setFriction(1);
    if (!zero_g) world.addRigidBody(ground.get());

    std::vector<btVector3> x(n);
    for (int i = 0; i < n; ++i) x[i] = btVector3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
    // Unit masses here; setTotalMass(.., true) below spreads the mass by adjacent face area, as
    // softshell does (m_i proportional to the sum of the areas of the triangles at i).
    body = new btSoftBody(&info, n, x.data(), nullptr);
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
  }

  ~BulletBalloon() {
    world.removeSoftBody(body);
    delete body;
    if (!zero_g) world.removeRigidBody(ground.get());
  }

  BulletBalloon(const BulletBalloon&) = delete;
  BulletBalloon& operator=(const BulletBalloon&) = delete;

  bool zero_g;
  // The links in the order they were appended, and Σ L0² over them.
  std::vector<std::pair<int, int>> edges;
  double sum_l2 = 0.0;
  // Declared in the order they must be made (each takes the ones before it).
  btSoftBodyRigidBodyCollisionConfiguration collision_configuration;
  btCollisionDispatcher dispatcher{&collision_configuration};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btSoftRigidDynamicsWorld world{&dispatcher, &broadphase, &solver, &collision_configuration};
  btBoxShape ground_shape{btVector3(50, 50, 50)};
  btDefaultMotionState ground_motion;
  std::unique_ptr<btRigidBody> ground;
  btSoftBody* body = nullptr;
};

}  // namespace peer
