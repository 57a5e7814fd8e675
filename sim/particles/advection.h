#pragma once
// Particle advection through the grid velocity and the solid-boundary correction (thesis
// Algorithm 1, the last stage of a step).
//
// advectRK2 is the explicit midpoint rule
//     x* = x + dt/2 u(x),    x' = x + dt u(x*),
// with u read from the staggered faces by sampleFaceVelocity (linear per component). For a linear
// field u = A x it gives x' = (I + dt A + dt^2/2 A^2) x: local error O(dt^3). For a rigid rotation
// with angle theta = omega dt per step the radius grows by the factor sqrt(1 + theta^4 / 4) exactly
// (|(1 - theta^2/2) + i theta|^2 = 1 + theta^4/4), and the position error is r theta^3 / 6 + O(theta^4).
#include "sparse_grid/vdb_trees.h"

#include <cmath>
#include <cstddef>

#include "sim/particles/grid_velocity.h"
#include "sim/particles/particles.h"
#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace particles {

/// Moves every particle one step dt along the face velocity u (midpoint rule, parallel).
/// Velocities and affine vectors are left alone (they come from G2P).
/// With `walls`, the velocity next to the domain's walls vanishes on them (BoxWalls).
template <int Dim>
void advectRK2(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& u, ParticleSet<Dim>& particles, double dt,
               const BoxWalls* walls = nullptr) {
  checkFaceArray<Dim>(layout, u, "advectRK2");
  const std::ptrdiff_t np = std::ptrdiff_t(particles.size());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t p = 0; p < np; ++p) {
    const Vec3d x = particles.x[p];
    const Vec3d mid = x + (0.5 * dt) * sampleFaceVelocity<Dim>(layout, u, x, walls);
    particles.x[p] = x + dt * sampleFaceVelocity<Dim>(layout, u, mid, walls);
  }
}

/// Central-difference gradient of phi at x with step h (the first Dim components; z = 0 in 2D).
template <int Dim, class Phi>
Vec3d levelSetGradient(const Phi& phi, const Vec3d& x, double h) {
  Vec3d grad(0.0);
  for (int a = 0; a < Dim; ++a) {
    Vec3d lo = x, hi = x;
    lo[a] -= h;
    hi[a] += h;
    grad[a] = (phi(hi) - phi(lo)) / (2.0 * h);
  }
  return grad;
}

/// Projects particles out of a solid. `phi(Vec3d) -> double` is a thread-safe signed distance,
/// negative inside the solid. A particle with phi < 0.1 dx takes Newton steps along the
/// central-difference gradient (step dx/100),  x <- x + (aim - phi) grad / |grad|^2  with
/// aim = 0.1 dx + 1e-6 dx, until 0.1 dx <= phi <= aim + 1e-4 dx (one or two steps for an exact
/// distance function; the gradient far inside a curved solid is less accurate, so a first step
/// may overshoot and the next ones come back; at most 8). Then the component of its velocity into
/// the solid is removed relative to the solid: with n = grad/|grad| at the new position and v_s =
/// solidVelocity(x), v <- v - min((v - v_s).n, 0) n. The affine vectors are left alone.
/// Particles where the gradient vanishes (|grad| < 1e-12) are left where they are.
/// Returns the number of particles moved. Parallel over particles.
template <int Dim, class Phi, class SolidVelocity>
std::size_t pushOutOfSolid(ParticleSet<Dim>& particles, const Phi& phi, const SolidVelocity& solidVelocity, double dx) {
  const double target = 0.1 * dx, aim = target + 1e-6 * dx, upper = aim + 1e-4 * dx, h = 0.01 * dx;
  constexpr int kMaxSteps = 8;
  const std::ptrdiff_t np = std::ptrdiff_t(particles.size());
  std::size_t moved = 0;
#pragma omp parallel for schedule(static) reduction(+ : moved)
  for (std::ptrdiff_t p = 0; p < np; ++p) {
    Vec3d x = particles.x[p];
    double value = phi(x);
    if (!(value < target)) continue;
    bool degenerate = false;
    for (int step = 0; step < kMaxSteps && (value < target || value > upper); ++step) {
      const Vec3d grad = levelSetGradient<Dim>(phi, x, h);
      const double g2 = grad.lengthSqr();
      if (g2 < 1e-24) {
        degenerate = true;
        break;
      }
      x += ((aim - value) / g2) * grad;
      value = phi(x);
    }
    if (degenerate) continue;
    particles.x[p] = x;
    const Vec3d grad = levelSetGradient<Dim>(phi, x, h);
    const double len = grad.length();
    if (len > 1e-12) {
      const Vec3d normal = grad / len;
      const double vn = (particles.v[p] - solidVelocity(x)).dot(normal);
      if (vn < 0.0) particles.v[p] -= vn * normal;
    }
    ++moved;
  }
  return moved;
}

/// pushOutOfSolid for a static solid (velocity 0).
template <int Dim, class Phi>
std::size_t pushOutOfSolid(ParticleSet<Dim>& particles, const Phi& phi, double dx) {
  return pushOutOfSolid<Dim>(particles, phi, [](const Vec3d&) { return Vec3d(0.0); }, dx);
}

}  // namespace particles
}  // namespace stokes::sim
