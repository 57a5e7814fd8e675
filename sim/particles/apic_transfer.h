#pragma once
// APIC transfers between particles and the staggered face grid (Jiang et al. 2015, "The Affine
// Particle-In-Cell Method"; thesis 3.4.1 and Algorithm 1), with quadratic B-spline weights.
//
// Weights. On the channel-a lattice (sim/particles/grid_velocity.h: face of cell i at lattice point i, a
// particle at lattice position g) the weight of face i is the tensor product
//     w_ip = prod_b N(g_b - i_b),   N(d) = 3/4 - d^2 (|d| < 1/2),  (3/2 - |d|)^2 / 2 (|d| < 3/2), 0.
// N is a partition of unity that reproduces linear functions, sum_i N(g - i) (i - g) = 0, and has
// the constant second moment sum_i N(g - i) (i - g)^2 = 1/4 for every g. So the APIC inertia-like
// matrix D_p = sum_i w_ip (x_i - x_p)(x_i - x_p)^T = dx^2/4 I, the same for every channel, and
// D_p^-1 = 4/dx^2 I.
//
// P2G (momentum form, unit particle mass):
//     m_f = sum_p w_fp,   (m u)_f = sum_p w_fp (v_pa + c_pa . (x_f - x_p)),   u_f = (m u)_f / m_f
// (u_f = 0 where m_f = 0). It is a scatter by block: the particles, binned by cell with a stable
// counting sort, are visited block by block in bin order, and each adds its weights to the 3^Dim
// nodes of each channel (cells k-1..k+2 of its cell k, so within one cell of its block along every
// axis but the far side, two). Blocks are coloured by the parity of their block coordinates:
// two blocks of one colour are at least one block apart, so their nodes never meet; the colours
// run one after another, each colour's blocks in parallel. A face's sum therefore runs colour by
// colour, and within a colour over one block's particles in bin order -- no atomics, and
// bit-identical for any thread count.
// Linear momentum is conserved: sum_f m_f u_f = sum_p v_p whenever every face a particle reaches
// is in the layout (partition of unity + linear reproduction).
//
// G2P:  v_pa = sum_f w_fp u_f,   c_pa = D_p^-1 sum_f w_fp u_f (x_f - x_p) = 4/dx^2 sum_f w_fp u_f (x_f - x_p).
// Together with P2G it conserves angular momentum: the particle angular momentum
//     L_p = x_p x v_p + dx^2/4 sum_a c_pa x e_a
// equals, after G2P, sum_f w_fp u_f x_f x e_a, so sum_p L_p = sum_f m_f u_f (x_f x e_a) = L_grid,
// and P2G maps sum_p L_p back to L_grid.
//
// Faces outside the layout are absent: P2G skips them (momentum that would land there is lost),
// and G2P renormalises by the weight W it found:
//     v_pa = sum_f w u_f / W,   c_pa = 4/dx^2 sum_f w (u_f - v_pa)(x_f - x_p) / W,
// which is the formula above when W = 1 (sum_f w (x_f - x_p) = 0) and keeps a constant field
// free of spurious affine terms near the layout's edge. Where W = 0 the particle keeps v_pa, c_pa.
// Particles whose cell is outside the layout contribute nothing to P2G.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sim/particles/grid_velocity.h"
#include "sim/particles/particles.h"
#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace particles {

/// Quadratic B-spline N(d), d in cell units (support |d| < 3/2). Both pieces are evaluated and
/// one selected, so the hot P2G loop does not branch on the (random) piece.
inline double quadraticBSpline(double d) {
  d = std::abs(d);
  const double t = std::max(1.5 - d, 0.0);
  const double inner = 0.75 - d * d, outer = 0.5 * t * t;
  return d < 0.5 ? inner : outer;
}

/// The three lattice nodes base, base+1, base+2 (base = floor(g - 1/2)) that carry the weight of
/// lattice position g, and their weights N(g - base - j).
struct QuadraticStencil {
  int base;
  std::array<double, 3> w;
};
inline QuadraticStencil quadraticStencil(double g) {
  QuadraticStencil st;
  st.base = int(std::floor(g - 0.5));
  for (int j = 0; j < 3; ++j) st.w[j] = quadraticBSpline(g - double(st.base + j));
  return st;
}

/// Inverse of the APIC matrix D_p = dx^2/4 I for quadratic B-splines (see the header comment).
inline double apicInverseInertia(double dx) { return 4.0 / (dx * dx); }

namespace detail {

/// Binned particle data in bin order (contiguous per cell): lattice position in cell units
/// g = (x - origin)/dx, velocity, affine vectors.
template <int Dim>
struct SortedParticles {
  std::vector<Vec3d> g, v;
  std::vector<typename ParticleSet<Dim>::Affine> c;
};

template <int Dim>
SortedParticles<Dim> sortParticles(const sparse_grid::BlockLayout<Dim>& layout, const ParticleSet<Dim>& particles,
                                   const ParticleBins& bins) {
  SortedParticles<Dim> sorted;
  const std::ptrdiff_t nb = std::ptrdiff_t(bins.binned());
  sorted.g.resize(nb);
  sorted.v.resize(nb);
  sorted.c.resize(nb);
  const double invDx = 1.0 / layout.dx();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t j = 0; j < nb; ++j) {
    const std::size_t p = bins.order[j];
    sorted.g[j] = (particles.x[p] - layout.origin()) * invDx;
    sorted.v[j] = particles.v[p];
    sorted.c[j] = particles.c[p];
  }
  return sorted;
}


/// The blocks that hold binned particles, in increasing order.
template <int Dim>
std::vector<std::uint32_t> blocksWithParticles(const sparse_grid::BlockLayout<Dim>& layout, const ParticleBins& bins) {
  constexpr std::size_t kSlots = sparse_grid::BlockLayout<Dim>::kSlots;
  std::vector<std::uint32_t> blocks;
  for (std::size_t b = 0; b < layout.numBlocks(); ++b)
    if (bins.start[(b + 1) * kSlots] > bins.start[b * kSlots]) blocks.push_back(std::uint32_t(b));
  return blocks;
}

/// `blocks` split into 2^Dim colours by the parity of their block coordinates (bit a: axis a),
/// in their order within a colour.
template <int Dim>
std::vector<std::vector<std::uint32_t>> blocksByParity(const sparse_grid::BlockLayout<Dim>& layout,
                                                       const std::vector<std::uint32_t>& blocks) {
  using Layout = sparse_grid::BlockLayout<Dim>;
  std::vector<std::vector<std::uint32_t>> colours(std::size_t(1) << Dim);
  for (std::uint32_t b : blocks) {
    int colour = 0;
    for (int a = 0; a < Dim; ++a) colour |= ((layout.blockOrigin(b)[a] >> Layout::kLog2Width) & 1) << a;
    colours[std::size_t(colour)].push_back(b);
  }
  return colours;
}

/// Slots of the cells [-1, kWidth + 1]^Dim around block b (local coordinates; -1 outside the layout),
/// x slowest: the nodes a particle of the block reaches.
template <int Dim>
struct BlockReach {
  using Layout = sparse_grid::BlockLayout<Dim>;
  static constexpr int kExtent = Layout::kWidth + 3;
  static constexpr int kCells = Dim == 2 ? kExtent * kExtent : kExtent * kExtent * kExtent;
  std::array<std::int64_t, kCells> slot;

  static int index(const Coord& local) {
    int idx = 0;
    for (int a = 0; a < Dim; ++a) idx = idx * kExtent + (local[a] + 1);
    return idx;
  }
  void fill(const sparse_grid::BlockLayout<Dim>& layout, std::size_t b) {
    for (int idx = 0; idx < kCells; ++idx) {
      Coord local(0, 0, 0);
      for (int a = Dim - 1, rest = idx; a >= 0; --a, rest /= kExtent) local[a] = rest % kExtent - 1;
      int code = 0, pow3 = 1;
      Coord inBlock = local;
      for (int a = 0; a < Dim; ++a, pow3 *= 3) {
        const int off = local[a] < 0 ? -1 : (local[a] >= Layout::kWidth ? 1 : 0);
        inBlock[a] -= off * Layout::kWidth;
        code += (off + 1) * pow3;
      }
      const std::int32_t nb = layout.neighbourBlock(b, code);
      slot[std::size_t(idx)] = nb < 0 ? -1 : std::int64_t(nb) * Layout::kSlots + Layout::localSlot(inBlock.x(), inBlock.y(), inBlock.z());
    }
  }
};

/// body(b, reach) for every block b of `blocks`, reach holding b's reach (BlockReach); the blocks
/// in parallel (dynamic: their particle counts differ) when `forked`, one table per thread, the
/// team counted as a region of kind `kind` (parallel/fork_policy.h).
template <int Dim, class Body>
void forBlocksWithReach(const sparse_grid::BlockLayout<Dim>& layout, const std::vector<std::uint32_t>& blocks, bool forked,
                        parallel::Region kind, const Body& body) {
#pragma omp parallel if (forked)
  {
    parallel::countTeam(kind);
    BlockReach<Dim> reach;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(blocks.size()); ++k) {
      const std::size_t b = blocks[std::size_t(k)];
      reach.fill(layout, b);
      body(b, reach);
    }
  }
}

/// Adds particle j's weights w and momenta w (v_a + c_a . (x_f - x_p)) to the nodes of every
/// channel (mass and momentum channel-major, n slots per channel).
template <int Dim>
void scatterParticle(const SortedParticles<Dim>& sorted, std::size_t j, const Coord& blockOrigin, const BlockReach<Dim>& reach,
                     std::size_t n, double dx, double* mass, double* momentum) {
  const Vec3d& g = sorted.g[j];
  // node i of axis b sits at lattice position i (h = 0: the channel's own axis) or i + 1/2 (h = 1:
  // across); d = g_b - that (cell units), x_f - x_p = -dx d
  std::array<std::array<int, Dim>, 2> baseOf;
  std::array<std::array<std::array<double, 3>, Dim>, 2> wOf, dOf;
  for (int h = 0; h < 2; ++h)
    for (int b = 0; b < Dim; ++b) {
      const double shifted = g[b] - (h == 0 ? 0.0 : 0.5);
      const int base = int(std::floor(shifted - 0.5));
      for (int k = 0; k < 3; ++k) {
        dOf[h][b][k] = shifted - double(base + k);
        wOf[h][b][k] = quadraticBSpline(dOf[h][b][k]);
      }
      baseOf[h][b] = base - blockOrigin[b];
    }
  for (int a = 0; a < Dim; ++a) {
    std::array<int, Dim> base;
    std::array<std::array<double, 3>, Dim> w, d;
    for (int b = 0; b < Dim; ++b) {
      const int h = b == a ? 0 : 1;
      base[b] = baseOf[h][b];
      w[b] = wOf[h][b];
      d[b] = dOf[h][b];
    }
    // the 3^Dim nodes, axis 0 slowest; w = prod_b w_b and c_a . d summed over b in axis order
    constexpr int E = BlockReach<Dim>::kExtent;
    const double va = sorted.v[j][a];
    const auto& ca = sorted.c[j][a];
    auto add = [&](double wn, double cDotD, int idx) {
      if (wn == 0.0) return;
      const std::int64_t s = reach.slot[std::size_t(idx)];
      if (s < 0) return;
      mass[std::size_t(a) * n + std::size_t(s)] += wn;
      momentum[std::size_t(a) * n + std::size_t(s)] += wn * (va - dx * cDotD);
    };
    for (int k0 = 0; k0 < 3; ++k0) {
      const double w0 = w[0][k0], c0 = ca[0] * d[0][k0];
      const int i0 = base[0] + k0 + 1;
      for (int k1 = 0; k1 < 3; ++k1) {
        const double w01 = w0 * w[1][k1], c01 = c0 + ca[1] * d[1][k1];
        const int i01 = i0 * E + base[1] + k1 + 1;
        if constexpr (Dim == 2) {
          add(w01, c01, i01);
        } else {
          for (int k2 = 0; k2 < 3; ++k2) add(w01 * w[2][k2], c01 + ca[2] * d[2][k2], i01 * E + base[2] + k2 + 1);
        }
      }
    }
  }
}

}  // namespace detail

/// P2G with precomputed bins (binParticles(layout, particles.x)). faceVelocity and faceMass are
/// resized to Dim * numSlots (channel-major) and fully overwritten. With SlotsToFill::ActiveCells
/// only the faces of active cells keep their sums; the others are 0 -- exact where every cell
/// within two cells of a particle is active (the simulator's layouts, whose band is >= 3 cells,
/// outside the domain box, where the faces are closed).
template <int Dim>
void particlesToGrid(const sparse_grid::BlockLayout<Dim>& layout, const ParticleSet<Dim>& particles, const ParticleBins& bins,
                     solver::Vector& faceVelocity, solver::Vector& faceMass,
                     sparse_grid::SlotsToFill slots = sparse_grid::SlotsToFill::All) {
  using Layout = sparse_grid::BlockLayout<Dim>;
  const std::size_t n = layout.numSlots();
  const double dx = layout.dx();
  const auto sorted = detail::sortParticles<Dim>(layout, particles, bins);
  faceVelocity.assign(Dim * n, 0.0);  // the momenta, then the velocities
  faceMass.assign(Dim * n, 0.0);
  double* momentum = faceVelocity.data();
  double* mass = faceMass.data();
  const bool forked = parallel::forkGridLoop(bins.binned());
  for (const auto& colour : detail::blocksByParity<Dim>(layout, detail::blocksWithParticles<Dim>(layout, bins)))
    detail::forBlocksWithReach<Dim>(layout, colour, forked, parallel::Region::ParticleScatter,
                                    [&](std::size_t b, const detail::BlockReach<Dim>& reach) {
      for (std::size_t j = bins.start[b * Layout::kSlots]; j < bins.start[(b + 1) * Layout::kSlots]; ++j)
        detail::scatterParticle<Dim>(sorted, j, layout.blockOrigin(b), reach, n, dx, mass, momentum);
    });
  const bool activeOnly = slots == sparse_grid::SlotsToFill::ActiveCells;
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(n))
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s) {
    const bool keep = !activeOnly || layout.isActiveCell(std::size_t(s));
    for (int a = 0; a < Dim; ++a) {
      const std::size_t f = std::size_t(a) * n + std::size_t(s);
      if (!keep) mass[f] = 0.0;
      momentum[f] = mass[f] > 0.0 ? momentum[f] / mass[f] : 0.0;
    }
  }
}

/// P2G: bins the particles by cell, then gathers (see the header comment).
template <int Dim>
void particlesToGrid(const sparse_grid::BlockLayout<Dim>& layout, const ParticleSet<Dim>& particles,
                     solver::Vector& faceVelocity, solver::Vector& faceMass,
                     sparse_grid::SlotsToFill slots = sparse_grid::SlotsToFill::All) {
  const ParticleBins bins = binParticles<Dim>(layout, particles.x);
  particlesToGrid<Dim>(layout, particles, bins, faceVelocity, faceMass, slots);
}

namespace detail {

/// G2P's sums at x (see the header comment) with channel a's node value read by
/// readNode(a, node, u) (node: the lattice node's cell coordinates; false where it is absent):
///     W = sum w, S0 = sum w u, S1 = sum w u (x_f - x_p), S2 = sum w (x_f - x_p),  x_f - x_p = dx (i - g),
/// over the 3^Dim nodes with axis 0 fastest, w = prod_b w_b in axis order.
template <int Dim, class ReadNode>
double gatherApicWith(const sparse_grid::BlockLayout<Dim>& layout, const Vec3d& x, const ReadNode& readNode, Vec3d& v,
                      typename ParticleSet<Dim>::Affine& c) {
  const double invD = apicInverseInertia(layout.dx());
  double minWeight = 1.0;
  for (int a = 0; a < Dim; ++a) {
    const Vec3d g = faceLatticePosition<Dim>(layout, x, a);
    std::array<QuadraticStencil, Dim> st;
    std::array<std::array<double, 3>, 3> r{};
    for (int b = 0; b < Dim; ++b) {
      st[b] = quadraticStencil(g[b]);
      for (int k = 0; k < 3; ++k) r[b][k] = layout.dx() * (double(st[b].base + k) - g[b]);
    }
    double W = 0.0, S0 = 0.0;
    Vec3d S1(0.0), S2(0.0);
    constexpr int K2 = Dim == 3 ? 3 : 1;
    for (int k2 = 0; k2 < K2; ++k2)
      for (int k1 = 0; k1 < 3; ++k1)
        for (int k0 = 0; k0 < 3; ++k0) {
          Coord node(st[0].base + k0, st[1].base + k1, 0);
          double w = st[0].w[k0] * st[1].w[k1];
          Vec3d rn(r[0][k0], r[1][k1], 0.0);
          if constexpr (Dim == 3) {
            node[2] = st[2].base + k2;
            w *= st[2].w[k2];
            rn[2] = r[2][k2];
          }
          double uf = 0.0;
          if (!readNode(a, node, uf)) continue;
          W += w;
          S0 += w * uf;
          S1 += (w * uf) * rn;
          S2 += w * rn;
        }
    minWeight = std::min(minWeight, W);
    if (W <= 0.0) continue;
    v[a] = S0 / W;
    c[a] = (invD / W) * (S1 - v[a] * S2);  // D^-1 sum w (u_f - v_a)(x_f - x_p) / W
  }
  return minWeight;
}

/// G2P at x, whose cell is `cell`; slotAt(offset) gives the slot of cell + offset or -1.
/// With `walls`, nodes beyond a wall of the box read their reflection (BoxWalls).
template <int Dim, class SlotAt>
double gatherApic(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& faceVelocity, const Vec3d& x,
                  const Coord& cell, const SlotAt& slotAt, const BoxWalls* walls, Vec3d& v,
                  typename ParticleSet<Dim>::Affine& c) {
  const std::size_t n = layout.numSlots();
  return gatherApicWith<Dim>(
      layout, x,
      [&](int a, const Coord& node, double& uf) { return readFaceNode<Dim>(faceVelocity, n, a, cell, node - cell, slotAt, walls, uf); },
      v, c);
}

/// gatherApic for a particle of block `origin` away from the walls, every node's slot read from
/// the block's reach table (the same sums in the same order: the same bits).
template <int Dim>
double gatherApicInBlock(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& faceVelocity, const Vec3d& x,
                         const Coord& origin, const BlockReach<Dim>& reach, Vec3d& v,
                         typename ParticleSet<Dim>::Affine& c) {
  const std::size_t n = layout.numSlots();
  return gatherApicWith<Dim>(
      layout, x,
      [&](int a, const Coord& node, double& uf) {
        const std::int64_t slot = reach.slot[std::size_t(BlockReach<Dim>::index(node - origin))];
        if (slot < 0) return false;
        uf = faceVelocity[std::size_t(a) * n + std::size_t(slot)];
        return true;
      },
      v, c);
}

}  // namespace detail

/// G2P at one position x: sets v[a] and c[a] of every channel with face weight W > 0 (renormalised
/// by W, see the header comment); channels with W = 0 keep their values. Returns the smallest W
/// over the channels (1 with full support). Thread-safe; one slotOf, then O(1) look-ups.
template <int Dim>
double gatherApic(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& faceVelocity, const Vec3d& x, Vec3d& v,
                  typename ParticleSet<Dim>::Affine& c, const BoxWalls* walls = nullptr) {
  const CellAnchor<Dim> anchor(layout, cellOfPosition<Dim>(layout, x));
  return detail::gatherApic<Dim>(layout, faceVelocity, x, anchor.cell,
                                 [&](const Coord& off) { return anchor.slotAt(off); }, walls, v, c);
}

/// G2P for every particle. Particles are taken block by block and cell by cell (binParticles): the
/// slots a block's particles reach are looked up once per block (detail::BlockReach) and its
/// particles read neighbouring faces (cache-friendly). Particles outside the layout use
/// gatherApic's slotOf fallback. Parallel over blocks; each particle is written by one thread only
/// (deterministic).
template <int Dim>
void gridToParticles(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& faceVelocity,
                     ParticleSet<Dim>& particles, const BoxWalls* walls = nullptr) {
  using Layout = sparse_grid::BlockLayout<Dim>;
  checkFaceArray<Dim>(layout, faceVelocity, "gridToParticles");
  const ParticleBins bins = binParticles<Dim>(layout, particles.x);
  detail::forBlocksWithReach<Dim>(
      layout, detail::blocksWithParticles<Dim>(layout, bins), parallel::forkGridLoop(bins.binned()),
      parallel::Region::ParticleGather, [&](std::size_t b, const detail::BlockReach<Dim>& reach) {
        const Coord& origin = layout.blockOrigin(b);
        for (std::size_t s = b * Layout::kSlots; s < (b + 1) * Layout::kSlots; ++s) {
          if (bins.count(s) == 0) continue;
          const Coord cell = layout.cellOf(s);
          // a reflected node of a particle inside the box lies within the block's reach (the mirror
          // of a ghost one or two nodes out is one the stencil reaches anyway); others are looked up
          const auto slotAt = [&](const Coord& off) {
            Coord local(0, 0, 0);
            for (int a = 0; a < Dim; ++a) {
              local[a] = cell[a] + off[a] - origin[a];
              if (local[a] < -1 || local[a] > Layout::kWidth + 1) return offsetSlot<Dim>(layout, s, off);
            }
            return reach.slot[std::size_t(detail::BlockReach<Dim>::index(local))];
          };
          const BoxWalls* cellWalls = walls && walls->near<Dim>(cell, 2) ? walls : nullptr;
          for (std::size_t j = bins.start[s]; j < bins.start[s + 1]; ++j) {
            const std::size_t p = bins.order[j];
            if (cellWalls)
              detail::gatherApic<Dim>(layout, faceVelocity, particles.x[p], cell, slotAt, cellWalls, particles.v[p],
                                      particles.c[p]);
            else
              detail::gatherApicInBlock<Dim>(layout, faceVelocity, particles.x[p], origin, reach, particles.v[p], particles.c[p]);
          }
        }
      });
  const std::ptrdiff_t np = std::ptrdiff_t(particles.size());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t p = 0; p < np; ++p)
    if (bins.slot[p] < 0) gatherApic<Dim>(layout, faceVelocity, particles.x[p], particles.v[p], particles.c[p], walls);
}

}  // namespace particles
}  // namespace stokes::sim
