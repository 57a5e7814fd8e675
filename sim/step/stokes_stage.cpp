// The grid side of one simulation step: see stokes_stage.h.
#include "sim/step/stokes_stage.h"

#ifdef STOKES_HAVE_PETSC
#endif

#include <openvdb/tools/Morphology.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <functional>
#include <limits>

#include "sim/geometry/band_phi.h"
#include "sim/ranks/block_halo.h"
#include "sim/ranks/block_values.h"
#include "sim/ranks/rank_comm.h"
#include "sim/particles/apic_transfer.h"
#include "sim/particles/grid_velocity.h"
#include "solver/krylov/stopwatch.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::sim {
inline namespace step {

using SC = sparse_grid::StressChannels<kSimDim>;

namespace {

solver::TileCacheStrategy cacheStrategy(TileCache c) {
  switch (c) {
    case TileCache::None: return solver::TileCacheStrategy::None;
    case TileCache::Library: return solver::TileCacheStrategy::Library;
    case TileCache::Shapes: return solver::TileCacheStrategy::Shapes;
  }
  throw std::invalid_argument("not a tile cache");
}

/// Reduced tiles of an affine / quadratic model (divergence-free basis; the decoupled viscosity
/// solve switches to the full basis, docs/design.md §3). Quadratic tiles fit on all their faces, affine
/// ones on their boundary. band_air >= 1 keeps tiles off the walls (stokes_stage.h).
std::optional<solver::ReducedOptions> reducedOptions(const ModelDesc& m, std::shared_ptr<solver::TileLibrary> library,
                                                     std::shared_ptr<solver::TileHistory> history) {
  if (m.type == ModelType::Uniform) return std::nullopt;
  solver::ReducedOptions r;
  r.order = m.type == ModelType::Affine ? solver::PolynomialOrder::Affine : solver::PolynomialOrder::Quadratic;
  r.family = solver::BasisFamily::DivergenceFree;
  r.fitAllFaces = r.order == solver::PolynomialOrder::Quadratic;
  r.tiling.tileSize = m.tile;
  r.tiling.padding = m.padding;
  r.tiling.bandAir = std::max(m.bandAir, 1);
  r.tiling.bandSolid = m.bandSolid;
  r.tiling.minRegion = m.minRegion;
  r.tiling.minTileSize = m.tileMin;
  r.tileAccuracy = m.tileAccuracy;
  r.cache = cacheStrategy(m.tileCache);
  r.library = std::move(library);
  r.history = std::move(history);
  return r;
}

bool outsideDomain(const openvdb::Coord& c, const DomainBox& d) {
  for (int b = 0; b < kSimDim; ++b) {
    if (c[b] < 0) return true;
    if (c[b] >= d.cells[b] && !(b == 1 && d.openTop)) return true;
  }
  return false;
}

using PhiFn = std::function<double(const Vec3d&)>;

/// Plane-cut weights below this are dropped to 0 (wetByPlanes). Plane cuts wet a sample by as
/// little as round-off, and a row carries W^2 of its weight: such rows slow the scenes' Jacobi
/// CG (the cantilever at res 32 / 64: 1,584 / 4,070 iterations a step, 1,094 / 2,837 with the
/// floor) and hold a sub-cell sliver the solve cannot resolve. 0.003 moves the analytic surface
/// mode's rate by under 0.1% at 7 of 8 places in its cell.
constexpr double kPlaneCutWeightFloor = 0.003;

/// W_L by plane cuts next to walls and solids (the plane-cut rule of GridStep::fillWeights). The
/// sub-sample rule reads the liquid extended into the solids, min(phi_L, max(phi_S - m, phi_L -
/// reach)) (extendIntoSolid), by its sign alone. A plane cut or a tent reads its value, and where
/// the liquid meets a wall that value is a ridge, not a plane: about 0 on the wall, where the
/// liquid's own surface meets it. The wall's edge then read 0.71 instead of 1 and a film draining
/// down the wall slipped (12% off at 4 cells across). So each region is
/// cut by its own plane and their fractions add:
///     W_L = min(1, W(phi_L) + W(phi_L - reach) (W(-phi_box - m) + W(phi_S - m))),
/// W the rule's kernel (`fractions(phi, out)`: tents for the faces' masses, the plane-cut ramp for
/// the rest). W(phi_L - reach) keeps the extension within reach of the liquid, as the sub-sample
/// rule's max does. The liquid and the solids overlap only by the particles' spheres reaching
/// past a wall, so the sum is the union's fraction, at most 1 where they do overlap. Weights
/// below kPlaneCutWeightFloor are dropped.
///
/// W(phi_L - reach) multiplies the walls' and solids' terms only. Without solids the liquid is
/// not sampled for it farther than 2 dx beyond the walls' shifted planes (walls(x) - m >= 2 dx):
/// +infinity there gives 0. Exact: a sample whose wall term is non-zero has walls(c) - m <= dx
/// (the kernels reach at most dx), and its plane's central differences sample within dx/4 of c,
/// where walls - m < 2 dx (walls is a distance, 1-Lipschitz).
template <class Fractions>
void wetByPlanes(std::size_t n, const Fractions& fractions, const PhiFn& liquid, const PhiFn& walls,
                 const PhiFn* solids, double reach, double margin, double dx, std::vector<double>& scratch, double* out) {
  scratch.resize(3 * n);
  double* inReach = scratch.data();
  double* wall = scratch.data() + n;
  double* solid = scratch.data() + 2 * n;
  fractions(liquid, out);
  fractions(
      [&](const Vec3d& x) {
        if (!solids && walls(x) - margin >= 2.0 * dx) return std::numeric_limits<double>::infinity();
        return liquid(x) - reach;
      },
      inReach);
  fractions([&](const Vec3d& x) { return walls(x) - margin; }, wall);
  if (solids) fractions([&](const Vec3d& x) { return (*solids)(x) - margin; }, solid);
  else std::fill(solid, solid + n, 0.0);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s) {
    const double w = std::min(1.0, out[s] + inReach[s] * (wall[s] + solid[s]));
    out[s] = w < kPlaneCutWeightFloor ? 0.0 : w;
  }
}

}  // namespace

DomainBox DomainBox::fromScene(const Scene& scene) {
  DomainBox d;
  d.dx = scene.dx();
  d.cells = scene.resolutionCells();
  d.min = scene.domainMin;
  for (int a = 0; a < 3; ++a) d.max[a] = d.min[a] + d.cells[a] * d.dx;
  d.openTop = scene.openTop;
  return d;
}

double DomainBox::phi(const Vec3d& x) const {
  if (!openTop) return boxSignedDistance(x, min, max);
  // the box without its +y side: per axis the signed distance beyond its faces, q_a, the top left
  // out; inside max_a q_a (<= 0), outside |max(q, 0)|. (A top face at the largest double gave a
  // box centre near 9e307 and rounded every distance inside it to 0: no liquid was ever seeded.)
  Vec3d q;
  for (int a = 0; a < 3; ++a) q[a] = std::max(min[a] - x[a], a == 1 ? -std::numeric_limits<double>::infinity() : x[a] - max[a]);
  const double inside = std::max({q[0], q[1], q[2]});
  if (inside <= 0.0) return inside;
  return Vec3d(std::max(q[0], 0.0), std::max(q[1], 0.0), std::max(q[2], 0.0)).length();
}

openvdb::MaskTree particleBandMask(const std::vector<Vec3d>& positions, const DomainBox& domain, int band) {
  openvdb::MaskTree mask;
  {
    openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(mask);
    const double invDx = 1.0 / domain.dx;
    for (const Vec3d& x : positions) {
      openvdb::Coord c;
      for (int a = 0; a < 3; ++a) c[a] = int(std::floor((x[a] - domain.min[a]) * invDx));
      acc.setValueOn(c);
    }
  }
  if (band > 0)
    openvdb::tools::dilateActiveValues(mask, band, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
  // One layer of cells past each upper wall: the stress samples on the wall (the lower edges of
  // those cells) hold the no-slip there as the cells with i_a = 0 hold it on the lower walls.
  // Their faces are closed and their other samples get no weight (GridStep::fillWeights).
  openvdb::CoordBBox clip = domain.cellBBox();
  for (int a = 0; a < kSimDim; ++a) clip.max()[a] += (a == 1 && domain.openTop) ? band : 1;  // air above an open top
  mask.clip(clip);
  mask.voxelizeActiveTiles();
  return mask;
}

std::vector<std::uint8_t> closedWallFaces(const Layout3& layout, const DomainBox& domain) {
  const std::size_t n = layout.numSlots();
  std::vector<std::uint8_t> closed(kSimDim * n, 0);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s) {
    const openvdb::Coord c = layout.cellOf(std::size_t(s));
    const bool outside = outsideDomain(c, domain);
    for (int a = 0; a < kSimDim; ++a) closed[a * n + s] = (outside || c[a] == 0) ? 1 : 0;
  }
  return closed;
}

solver::StepOptions StokesPlan::optionsFor(std::size_t liquidCells, double viscousNumber) const {
  solver::SolveRequest r = request;
  r.liquidCells = liquidCells;
  r.viscousNumber = viscousNumber;
  solver::StepOptions o = options;
  solver::applyPlan(solver::planSolve(r), o);
  return o;
}

StokesPlan planStokes(const Scene& scene, std::shared_ptr<solver::TileLibrary> library,
                      std::shared_ptr<solver::TileHistory> history) {
  StokesPlan plan;
  // form, method and preconditioner: solver/step/solve_plan.h decides, per step (optionsFor)
  solver::SolveRequest& request = plan.request;
  request.system = scene.stepSystem();
  request.reducedTiles = scene.model.type != ModelType::Uniform;
  request.preconditioner = scene.solver.preconditioner;
  request.pressureVelocityMethod = scene.solver.multigridMethod;
  request.tileRule = scene.model.tileRule;
  request.backend = scene.solver.backend;
  try {
    solver::checkRequest(request);
  } catch (const std::invalid_argument& e) {
    const bool decoupled = request.system == solver::SystemKind::DecoupledStokes;
    throw std::invalid_argument(std::string("solver: ") + e.what() + (decoupled ? " (use viscosity mode \"coupled\")" : ""));
  }
  solver::StepOptions& o = plan.options;
  o.system = request.system;  // a decoupled step runs its two solves itself (GridStep::solve)
  o.rows = scene.solver.rows;
  o.rowStencils = scene.solver.rowStencils;
  o.multigrid.smootherDegree = scene.solver.multigridDegree;
  o.krylov.relativeTolerance = scene.solver.tolerance;
  o.krylov.maxIterations = scene.solver.maxIterations;
  o.reduced = reducedOptions(scene.model, std::move(library), std::move(history));
  return plan;
}

namespace {

/// Cells past a rank's blocks whose liquid weights and u* it needs from their owners: the
/// stencils' and face masses' reach (3), or with reduced tiles that each rank builds near its
/// blocks, theirs (solver::distributedTileDepth). Adaptive tiles gather the whole problem instead
/// (GridStep::solveWholeOnEveryRank).
int rankWeightsDepth(const Scene& scene) {
  constexpr int kStencilDepth = 3;
  const std::optional<solver::ReducedOptions> reduced = reducedOptions(scene.model, nullptr, nullptr);
  if (!reduced || reduced->tiling.minTileSize > 0) return kStencilDepth;
  return std::max(kStencilDepth, solver::distributedTileDepth(reduced->tiling));
}

}  // namespace

GridStep::GridStep(const std::vector<Vec3d>& positions, const openvdb::FloatGrid& liquid, const ShapeField* solids,
                   const DomainBox& domain, const Scene& scene, double dt, bool needStressWeights, int band,
                   const RankBlocks* part)
    : domain_(domain), solids_(solids), part_(part), haloDepth_(3 + 2 + std::max(1, int(std::ceil(scene.cfl)))),
      weightsDepth_(rankWeightsDepth(scene)) {
  auto t0 = std::chrono::steady_clock::now();
  layout_ = std::make_unique<Layout3>(
      part ? part->mask(part->ownedAndHalo(std::max(haloDepth_, weightsDepth_)))
           : particleBandMask(positions, domain, band),
      domain.dx, domain.min);
  problem_.layout = layout_.get();
  if (part) {
    problem_.rank = part->rank;
    problem_.blockOwner.resize(layout_->numBlocks());
    for (std::size_t b = 0; b < layout_->numBlocks(); ++b)
      problem_.blockOwner[b] = part->owner[std::size_t(part->blockOf(layout_->blockOrigin(b)))];
  }
  problem_.rho = scene.material.density;
  problem_.mu = scene.hasViscosity() ? scene.material.viscosity : 0.0;
  problem_.dt = dt;
  problem_.allocate(/*withSolids=*/solids != nullptr);
  problem_.closedFace = closedWallFaces(*layout_, domain);
  for (std::size_t s = 0; s < layout_->numSlots(); ++s) report_.cells += layout_->isActiveCell(s) && problem_.ownsSlot(s) ? 1 : 0;
  finishStage(Stage::Layout, t0);

  t0 = std::chrono::steady_clock::now();
  fillWeights(liquid, solids, needStressWeights, scene.liquidWeights);
  finishStage(Stage::Weights, t0);
}

void GridStep::fillWeights(const openvdb::FloatGrid& liquid, const ShapeField* solids, bool needStressWeights,
                           sparse_grid::FractionRule rule) {
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
  const BandPhi liquidPhi(liquid.copy(), L);  // GridPhi's samples, read from per-block copies
  // The liquid extended into the solids it touches (thesis 3.6.4, Fig. 3.4c), and likewise into
  // the domain walls, whose solid is the outside of the box (phi = -phi_box): a wall's edge and
  // face samples then have their full liquid weight, so the wall holds the liquid as a solid does
  // (clipped to the box instead, they had half, and a layer sheared against the floor slipped by
  // about 3 dx).
  const double reach = kSolidExtensionCells * domain_.dx, margin = kWettingMarginCells * domain_.dx;
  // phi_S where it can matter: farther than 2 reach from the liquid the extension changes
  // nothing (extendIntoSolid's min is phi_L; a wall's plane is cut off by W(phi_L - reach)), so
  // the solids' distance is skipped there.
  auto solidNearLiquid = [&](const Vec3d& x, double phiL) {
    return phiL < 2.0 * reach ? solids->phi(x) : std::numeric_limits<double>::max();
  };
  auto phi = [&](const Vec3d& x) {
    const double phiL = liquidPhi(x);
    const double extended = solids ? extendIntoSolid(phiL, solidNearLiquid(x, phiL), reach, margin) : phiL;
    return extendIntoSolid(extended, -domain_.phi(x), reach, margin);
  };
  // Samples outside the box (the cells past the upper walls) hold no liquid; those on a wall do.
  // The liquid lies at least band - 1 cells inside the layout's active cells (particleBandMask:
  // the particles' cells dilated by the band, radius-1-cell spheres), so inactive slots hold none.
  const double outside = 1e-9 * domain_.dx;
  auto clipToBox = [&](sparse_grid::StaggerMask mask, double* out) {
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s)
      if (out[s] != 0.0 && domain_.phi(L.samplePosition(std::size_t(s), mask)) > outside) out[s] = 0.0;
  };
  // The plane-cut rule reads the liquid and each wall or solid from its own plane (wetByPlanes).
  const PhiFn liquidOnly = [&](const Vec3d& x) { return double(liquidPhi(x)); };
  const PhiFn wallPhi = [&](const Vec3d& x) { return -domain_.phi(x); };
  const PhiFn solidPhi = [&](const Vec3d& x) { return solidNearLiquid(x, liquidPhi(x)); };
  std::vector<double> scratch;
  // W_L of sample kind `mask` (faces: axis >= 0, their mass fractions) into `out`.
  auto liquidWeights = [&](sparse_grid::StaggerMask mask, int axis, double* out) {
    auto fractions = [&](const auto& f, double* o) {
      if (axis >= 0) sparse_grid::computeLiquidFaceFractions<kSimDim>(L, axis, f, o, rule, sparse_grid::SlotsToFill::ActiveCells);
      else sparse_grid::computeLiquidFractions<kSimDim>(L, mask, f, o, rule, sparse_grid::SlotsToFill::ActiveCells);
    };
    if (rule == sparse_grid::FractionRule::PlaneCut)
      wetByPlanes(n, fractions, liquidOnly, wallPhi, solids ? &solidPhi : nullptr, reach,
                  kPlaneCutWettingMarginCells * domain_.dx, domain_.dx, scratch, out);
    else fractions(phi, out);
    clipToBox(mask, out);
  };
  for (int a = 0; a < kSimDim; ++a)  // W_L^u, the faces' mass fractions
    liquidWeights(sparse_grid::faceMask(a), a, problem_.liquidFace.data() + a * n);
  liquidWeights(sparse_grid::kCellCentre, -1, problem_.liquidCell.data());
  if (needStressWeights) {
    // The diagonal stress channels sit at the cell centres: W_L^tau_aa = W_L^p.
    for (int c = 0; c < SC::kCount; ++c) {
      double* out = problem_.liquidStress.data() + c * n;
      if (SC::isDiagonal(c)) std::copy(problem_.liquidCell.begin(), problem_.liquidCell.end(), out);
      else liquidWeights(SC::mask(c), -1, out);
    }
    fillFluidStressWeights(solids);
  }
  if (!solids) return;
  // W_F^u = plane-cut fraction of a face's control volume outside the solids (-phi_solid < 0),
  // continuous in the solid's position like W_F^tau: it sets how much of a cut face the solid's
  // velocity prescribes (b = K^T (W_F u* + (1 - W_F) u_solid)).
  auto fluidPhi = [&](const Vec3d& x) { return -solids->phi(x); };
  for (int a = 0; a < kSimDim; ++a)
    sparse_grid::computePlaneCutFractions<kSimDim>(L, sparse_grid::faceMask(a), fluidPhi, problem_.fluidFace.data() + a * n);
  // A face with less fluid than the smallest mass weight is the solid's (Dirichlet): the
  // pressure-velocity form's velocity block (rho/dt) W_F W_m + W_F V W_F has W_F^2 on its
  // diagonal, and plane-cut slivers of 1e-3 left it nearly singular (MINRES + block multigrid
  // stalled at relative residual 1 on the beam). 27 sub-samples never gave less than 1/27.
  for (double& w : problem_.fluidFace)
    if (w < problem_.minMassWeight) w = 0.0;
  report_.builtFluidWeights = true;
  if (solids->moving()) fillSolidVelocity(*solids);
}

void GridStep::fillFluidStressWeights(const ShapeField* solids) {
  // W_F^tau: the plane-cut fraction of each stress sample's control volume inside the box and
  // outside the solids, psi = max(-phi_solid, phi_box) < 0. It puts the no-slip plane on the wall
  // or the solid surface (StaggeredProblem::fluidStress); n^3 sub-samples would move it by up to
  // dx/6 (a wall through a sample reads 1/3 or 2/3 instead of 1/2). Without solids and with the
  // liquid off every wall it is 1 everywhere and is not stored.
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
  auto psi = [&](const Vec3d& x) {
    const double box = domain_.phi(x);
    return solids ? std::max(-solids->phi(x), box) : box;
  };
  solver::Vector& w = problem_.fluidStress;
  w.assign(SC::kCount * n, 1.0);
  for (int c = 0; c < SC::kCount; ++c) {
    if (SC::isDiagonal(c) && c > 0) {  // the diagonal channels share the cell-centre samples
      std::copy(w.begin(), w.begin() + std::ptrdiff_t(n), w.begin() + std::ptrdiff_t(c * n));
      continue;
    }
    sparse_grid::computePlaneCutFractions<kSimDim>(L, SC::mask(c), psi, w.data() + c * n);
  }
  if (solids) return;
  bool cut = false;
  for (std::size_t i = 0; i < w.size() && !cut; ++i)
    cut = w[i] < 1.0 && problem_.liquidStress[i] > 0.0;
  if (!cut) w.clear();  // no liquid stress sample is cut by a wall: W_F^tau = 1
}

void GridStep::fillSolidVelocity(const ShapeField& solids) {
  // u_solid on every face the solid covers (W_F < 1), the velocity of the solid there; closed wall
  // faces stay 0 (the domain box does not move).
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s)
    for (int a = 0; a < kSimDim; ++a) {
      const std::size_t i = a * n + std::size_t(s);
      if (problem_.fluidFace[i] >= 1.0 || problem_.closedFace[i]) continue;
      problem_.uSolid[i] = solids.velocityAt(L.samplePosition(std::size_t(s), sparse_grid::faceMask(a)))[a];
    }
}

void GridStep::setInflow(const std::function<double(const Vec3d&)>& phi, const Vec3d& velocity) {
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
  if (problem_.fluidFace.empty()) {  // no solids: every face is fluid but the inflow's
    problem_.fluidFace.assign(kSimDim * n, 1.0);
    problem_.uSolid.assign(kSimDim * n, 0.0);
  }
  inflow_.resize(kSimDim * n, 0);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s)
    for (int a = 0; a < kSimDim; ++a) {
      const std::size_t i = a * n + std::size_t(s);
      if (problem_.closedFace[i] || !(phi(L.samplePosition(std::size_t(s), sparse_grid::faceMask(a))) < 0.0)) continue;
      problem_.fluidFace[i] = 0.0;
      problem_.uSolid[i] = velocity[a];
      inflow_[i] = 1;
    }
}

std::string GridStep::faceName(std::size_t i) const {
  const std::size_t n = layout_->numSlots();
  const openvdb::Coord c = layout_->cellOf(i % n);
  static const char* axes = "xyz";
  return std::string("face ") + axes[i / n] + " of cell (" + std::to_string(c.x()) + "," + std::to_string(c.y()) +
         "," + std::to_string(c.z()) + ")";
}

std::string GridStep::worstDivergenceCell() const {
  // |W_L^p (div u - s)| per cell, div u = sum_a (u_a(i + e_a) - u_a(i)) / dx: where the velocity
  // of an unconverged solve is furthest from incompressible
  const std::size_t n = layout_->numSlots();
  double worst = -1.0;
  std::size_t at = 0;
  for (std::size_t slot = 0; slot < n; ++slot) {
    const double w = problem_.liquidCell[slot];
    if (!(w > 0.0) || !problem_.ownsSlot(slot)) continue;  // split over ranks: this rank's cells
    double div = 0.0;
    for (int a = 0; a < kSimDim; ++a) {
      const std::int64_t up = layout_->neighbourSlot(slot, a, +1);
      const double high = up >= 0 ? velocity_[std::size_t(a) * n + std::size_t(up)] : 0.0;
      div += high - velocity_[std::size_t(a) * n + slot];
    }
    const double r = std::abs(w * (div / layout_->dx() - problem_.divergenceTarget));
    if (r > worst) {
      worst = r;
      at = slot;
    }
  }
  if (worst < 0.0) return "no liquid cell";
  const openvdb::Coord c = layout_->cellOf(at);
  const Vec3d x = layout_->samplePosition(at, sparse_grid::kCellCentre);
  char buf[160];
  std::snprintf(buf, sizeof buf, "cell (%d,%d,%d) at (%.4g, %.4g, %.4g) m, |div u - s| = %.3g 1/s", c.x(), c.y(),
                c.z(), x.x(), x.y(), x.z(), worst / problem_.liquidCell[at]);
  return buf;
}

void GridStep::finishStage(Stage stage, std::chrono::steady_clock::time_point t0) {
  report_.times.add(stage, solver::secondsSince(t0));
  report_.stages.push_back(stage);
}

void GridStep::solve(const ParticleSet<kSimDim>& particles, const Vec3d* gravity, const StokesPlan& plan,
                     const WarmStart<kSimDim>* warm) {
  const std::size_t m = kSimDim * layout_->numSlots();
  const auto t0 = std::chrono::steady_clock::now();
  // The layout holds every cell within its band (>= 3) of a particle inside the box: P2G on the
  // active cells alone is exact there, and the faces beyond the walls are closed below.
  particlesToGrid<kSimDim>(*layout_, particles, problem_.uStar, faceMass_, sparse_grid::SlotsToFill::ActiveCells);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(m); ++i)
    if (problem_.closedFace[i]) problem_.uStar[i] = 0.0;
  finishStage(Stage::P2G, t0);
  solveFromStart(gravity, plan, warm);
}

void GridStep::setStartVelocity(const std::function<double(int, const Vec3d&)>& u) {
  const std::size_t n = layout_->numSlots();
  const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s)
    for (int a = 0; a < kSimDim; ++a) {
      const std::size_t i = std::size_t(a) * n + std::size_t(s);
      const bool open = layout_->isActiveCell(std::size_t(s)) && !problem_.closedFace[i];
      problem_.uStar[i] = open ? u(a, layout_->samplePosition(std::size_t(s), sparse_grid::faceMask(a))) : 0.0;
    }
  finishStage(Stage::P2G, t0);
}

solver::Vector GridStep::pressure() const {
  const std::size_t n = layout_->numSlots();
  if (solution_.size() < pressureOffset_ + n) return {};
  return solver::Vector(solution_.begin() + std::ptrdiff_t(pressureOffset_),
                        solution_.begin() + std::ptrdiff_t(pressureOffset_ + n));
}

void GridStep::solveFromStart(const Vec3d* gravity, const StokesPlan& plan, const WarmStart<kSimDim>* warm) {
  const std::size_t m = kSimDim * layout_->numSlots();
  auto t0 = std::chrono::steady_clock::now();
  if (gravity) {
    // u* += g dt on every open face (thesis Algorithm 1: body forces before the Stokes step)
    t0 = std::chrono::steady_clock::now();
    const std::size_t n = layout_->numSlots();
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(m); ++i)
      if (!problem_.closedFace[i]) problem_.uStar[i] += (*gravity)[int(std::size_t(i) / n)] * problem_.dt;
    finishStage(Stage::Gravity, t0);
  }
  bool finite = true;
#pragma omp parallel for schedule(static) reduction(&& : finite)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(m); ++i) finite = finite && std::isfinite(problem_.uStar[i]);
  if (!everyRank(finite)) {  // name the first such face
    for (std::size_t i = 0; i < m; ++i)
      if (!std::isfinite(problem_.uStar[i]))
        throw SimulationError("stage p2g: non-finite velocity u* on " + faceName(i));
    throw SimulationError("stage p2g: non-finite velocity u* on another rank");
  }

  if (part_) takeHaloWeightsFromOwners();

  // the solver for this step's size and viscous number (an open preconditioner follows them:
  // solver/step/solve_plan.h); split over ranks, the liquid cells of all ranks
  std::size_t liquidCells = 0;
  for (std::size_t s = 0; s < problem_.liquidCell.size(); ++s)
    liquidCells += problem_.liquidCell[s] > 0.0 && problem_.ownsSlot(s) ? 1 : 0;
  if (part_) liquidCells = std::size_t(sumOverRanks(std::int64_t(liquidCells)));
  const solver::StepOptions options = plan.optionsFor(liquidCells, problem_.viscousNumber());
  switch (plan.request.system) {
    case solver::SystemKind::UnifiedStokes: {
      runSolve(Stage::Stokes, options, warm);
      const std::size_t n = layout_->numSlots();
      for (std::size_t i = 0; i < problem_.liquidStress.size(); ++i)
        report_.stressUnknowns += problem_.liquidStress[i] > 0.0 && problem_.ownsSlot(i % n) ? 1 : 0;
      break;
    }
    case solver::SystemKind::DecoupledStokes: {
      // viscosity (full basis on tiles: its input is not divergence-free), then the projection
      solver::StepOptions visc = options;
      visc.system = solver::SystemKind::Viscosity;
      if (visc.reduced) visc.reduced->family = solver::BasisFamily::Full;
      runSolve(Stage::Viscosity, visc);
      problem_.uStar = velocity_;
      solver::StepOptions proj = options;
      proj.system = solver::SystemKind::PressureProjection;
      runSolve(Stage::Pressure, proj, warm);
      break;
    }
    case solver::SystemKind::PressureProjection: {
      solver::StepOptions proj = options;
      proj.system = solver::SystemKind::PressureProjection;
      runSolve(Stage::Pressure, proj, warm);
      break;
    }
    case solver::SystemKind::Viscosity: {  // never a scene's step (Scene::stepSystem)
      throw std::logic_error("GridStep::solve: a scene step runs unified Stokes, the decoupled pair or the projection");
    }
  }
  t0 = std::chrono::steady_clock::now();
  // split over ranks: the halo's velocities that the extrapolation (3 layers), G2P (2 cells) and
  // advection (up to cfl cells further) read, from their owners
  if (part_) report_.sentBytes += exchangeHaloValues(*layout_, *part_, {&velocity_}, haloDepth_);
  extrapolate(3);
  finishStage(Stage::Extrapolate, t0);
}

void GridStep::takeHaloWeightsFromOwners() {
  // The liquid weights and u* of the halo cells within weightsDepth_ of this rank's blocks (what
  // its rows' stencils, the face masses' lending and the tiles it builds read), as their owners
  // computed them: the operator is then the same on both sides of every rank boundary by
  // construction, whatever the ghosts' reach (the solids' weights, walls and inflow are pointwise
  // and need no exchange).
  report_.sentBytes += exchangeHaloValues(
      *layout_, *part_, {&problem_.liquidFace, &problem_.liquidCell, &problem_.liquidStress, &problem_.uStar},
      weightsDepth_);
}

solver::StepReport GridStep::solveWholeOnEveryRank(const solver::StepOptions& options, solver::Vector* solution,
                                                  const solver::Vector& guess, std::size_t channels) {
  // Every rank gathers the blocks the others own into the step's whole problem (the same bits on
  // every rank: each block's values come from its owner), solves it with the others, and keeps
  // its own blocks' and halo's velocities and solution.
  const Layout3 whole(part_->mask(std::vector<std::uint8_t>(part_->size(), 1)), domain_.dx, domain_.min);
  Problem3 w;
  w.layout = &whole;
  w.rho = problem_.rho, w.mu = problem_.mu, w.dt = problem_.dt;
  w.minMassWeight = problem_.minMassWeight, w.divergenceTarget = problem_.divergenceTarget;
  const std::size_t n = layout_->numSlots();
  std::size_t sent = 0;
  // an array some rank holds (the others: `fill`), gathered; empty where no rank holds it
  auto gather = [&](const solver::Vector& mine, std::size_t width, double fill, solver::Vector& to) {
    if (allRanks(mine.empty())) return;
    sent += gatherWholeValues(*layout_, mine.empty() ? solver::Vector(width * n, fill) : mine, *part_, whole, to);
  };
  constexpr std::size_t kStress = SC::kCount;
  gather(problem_.liquidFace, kSimDim, 0.0, w.liquidFace);
  gather(problem_.liquidCell, 1, 0.0, w.liquidCell);
  gather(problem_.liquidStress, kStress, 0.0, w.liquidStress);
  gather(problem_.fluidFace, kSimDim, 1.0, w.fluidFace);
  gather(problem_.fluidStress, kStress, 1.0, w.fluidStress);
  gather(problem_.uStar, kSimDim, 0.0, w.uStar);
  gather(problem_.uSolid, kSimDim, 0.0, w.uSolid);
  w.closedFace = closedWallFaces(whole, domain_);
  solver::Vector wholeGuess, u, x;
  gather(guess, channels, 0.0, wholeGuess);
  solver::StepReport rep = solver::solveStep(w, options, u, solution ? &x : nullptr, wholeGuess.empty() ? nullptr : &wholeGuess);
  // this rank's blocks and halo, from the whole
  auto local = [&](const solver::Vector& from, solver::Vector& to) {
    const std::size_t N = whole.numSlots(), width = from.size() / N, kSlots = Layout3::kSlots;
    to.assign(width * n, 0.0);
    for (std::size_t b = 0; b < layout_->numBlocks(); ++b) {
      const std::size_t wb = std::size_t(whole.blockAt(layout_->blockOrigin(b)));
      for (std::size_t c = 0; c < width; ++c)
        std::copy_n(from.begin() + std::ptrdiff_t(c * N + wb * kSlots), kSlots, to.begin() + std::ptrdiff_t(c * n + b * kSlots));
    }
  };
  local(u, velocity_);
  if (solution) local(x, *solution);
  rep.sentBytes += sent;
  return rep;
}

void GridStep::runSolve(Stage stage, const solver::StepOptions& options,
                        const WarmStart<kSimDim>* warm) {
  const auto t0 = std::chrono::steady_clock::now();
  solver::StepReport rep;
  // The solve's unknowns carry over to the next step, moved by cell (solver::solutionChannels; a
  // step of another form or system finds no guess). The pressure-velocity form starts from the
  // previous step's u, p and multipliers, not from u*: u* differs from the solution by g dt and
  // the particles' noise, which the pressure and viscosity remove (pile at rest, res 448: 57-59
  // against 89-100 iterations a step; u* as the velocity guess saved none).
  const bool carries = options.system != solver::SystemKind::Viscosity;
  const std::size_t channels = solver::solutionChannels<kSimDim>(options.system, options.form);
  solver::Vector guess;
  if (carries && warm) guess = warm->guessFor(*layout_, channels);
  solver::Vector solution;
  try {
    // a step split over ranks solves its part on every rank, each building the tiles near its
    // blocks, or with adaptive tiles (whose split test reads the whole liquid) the whole problem
    if (problem_.isDistributed() && options.reduced && options.reduced->tiling.minTileSize > 0)
      rep = solveWholeOnEveryRank(options, carries ? &solution : nullptr, guess, channels);
    else
      rep = solver::solveStep(problem_, options, velocity_, carries ? &solution : nullptr, guess.empty() ? nullptr : &guess);
  } catch (const std::invalid_argument& e) {
    throw SimulationError(std::string("stage ") + stageName(stage) + ": " + e.what());
  }
  finishStage(stage, t0);
  report_.iterations += rep.solve.iterations;
  report_.unknowns += rep.unknowns;
  report_.krylovRows += rep.krylovRows;
  report_.stencilSlots += rep.stencilSlots;
  report_.krylovSeconds += rep.solveSeconds;
  report_.setupSeconds += rep.preconditionerSeconds;
  report_.solver += (report_.solver.empty() ? "" : "; ") + rep.solver;
  report_.tiles += rep.tiles;
  report_.fallbackTiles += rep.fallbackTiles;
  report_.partialTiles += rep.partialTiles;
  report_.unpaidTiles += rep.unpaidTiles;
  report_.keptTiles += rep.keptTiles;
  report_.sentBytes += rep.sentBytes;
  report_.tileDofs += rep.reducedDofs;
  report_.relativeResidual = std::max(report_.relativeResidual, rep.solve.relativeResidual);
  if (rep.solve.status == solver::Status::Interrupted)
    throw StepInterrupted(std::string("stage ") + stageName(stage) + ": stopped on request after " +
                          std::to_string(rep.solve.iterations) + " iterations");
  if (!rep.solve.converged())
    throw SimulationError(std::string("stage ") + stageName(stage) + ": the " + solver::toString(options.system) +
                          " solve did not converge (status " + solver::toString(rep.solve.status) + " after " +
                          std::to_string(rep.solve.iterations) + " iterations, relative residual " +
                          std::to_string(rep.solve.relativeResidual) + ", tolerance " +
                          std::to_string(options.krylov.relativeTolerance) + ", " +
                          std::to_string(rep.unknowns) + " unknowns; " + rep.diagnostics +
                          "; largest divergence left" + (part_ ? " on rank " + std::to_string(part_->rank) + "'s blocks" : "") +
                          " at " + worstDivergenceCell() + ")");
  // tiles that fell back to Cartesian cells: named once per step (the step itself is fine)
  if (rep.fallbackTiles > 0) std::fprintf(stderr, "[stokesvdb] stage %s: %s\n", stageName(stage), rep.diagnostics.c_str());
  // (a rank's own faces: the halo's come from their owners after the solve)
  const std::size_t n = layout_->numSlots();
  std::size_t bad = velocity_.size();
  for (std::size_t i = 0; i < velocity_.size() && bad == velocity_.size(); ++i)
    if (problem_.ownsSlot(i % n) && !std::isfinite(velocity_[i])) bad = i;
  if (!everyRank(bad == velocity_.size()))
    throw SimulationError(std::string("stage ") + stageName(stage) + ": non-finite velocity on " +
                          (bad < velocity_.size() ? faceName(bad) : std::string("another rank")));
  if (carries) {
    solution_ = std::move(solution);
    // the pressure's channel: after the velocity on the pressure-velocity form, first otherwise
    const bool pv = options.system == solver::SystemKind::UnifiedStokes &&
                    options.form == solver::StokesForm::PressureVelocity;
    pressureOffset_ = pv ? std::size_t(kSimDim) * layout_->numSlots() : 0;
  }
}

void GridStep::extrapolate(int layers) {
  // Faces that hold liquid (solved), lie on a wall or inside a solid (W_F = 0: the solid's
  // velocity) are known; the rest take the mean of their known neighbours, layer by layer, so G2P
  // and advection near the surface read liquid velocities. A solid face must stay known: filled
  // with the liquid's velocity it lets G2P and advection slide particles along the solid, undoing
  // the no-slip the solve imposed (the beam slid off its block this way).
  const std::size_t m = velocity_.size();
  std::vector<std::uint8_t> known(m);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(m); ++i)
    known[i] = (problem_.liquidFace[i] > 0.0 || problem_.closedFace[i] || problem_.fluidFaceWeight(i) <= 0.0) ? 1 : 0;
  extrapolateFaceVelocities<kSimDim>(*layout_, velocity_, known, layers);
  if (solids_) setSolidGhostVelocities(*solids_);
  for (std::size_t i = 0; i < inflow_.size(); ++i)
    if (inflow_[i]) velocity_[i] = problem_.uSolid[i];
}

void GridStep::setSolidGhostVelocities(const ShapeField& solids) {
  // A face g inside a solid (W_F = 0) next to a liquid face f of its channel (one cell away along
  // b) takes the linear extrapolation through the solid surface, which lies a fraction
  // theta = phi_S(f) / (phi_S(f) - phi_S(g)) of the way from f to g:
  //     u_g = u_s + (u_s - u_f) (1 - theta) / theta,
  // so G2P and advection interpolate u_s on the surface (the ghost-fluid value; with u_g = u_s the
  // interpolant reached u_s only at g, half a cell too deep for a surface through the edge, and
  // particles next to the solid slipped). theta >= 1/4 bounds the extrapolation's gain to 3;
  // several liquid neighbours are averaged with weights theta. Written after the solve and the
  // extrapolation, so nothing else reads it.
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
  const std::ptrdiff_t m = std::ptrdiff_t(velocity_.size());
  solver::Vector ghost(velocity_);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t i = 0; i < m; ++i) {
    if (problem_.fluidFaceWeight(std::size_t(i)) > 0.0 || problem_.closedFace[i]) continue;
    if (!inflow_.empty() && inflow_[i]) continue;  // prescribed by an inflow, not inside a solid
    const int a = int(std::size_t(i) / n);
    const std::size_t s = std::size_t(i) % n;
    double sum = 0.0, weights = 0.0, phiG = 0.0;
    bool havePhiG = false;
    for (int b = 0; b < kSimDim; ++b)
      for (int dir = -1; dir <= 1; dir += 2) {
        const std::int64_t t = L.neighbourSlot(s, b, dir);
        if (t < 0) continue;
        const std::size_t f = a * n + std::size_t(t);
        if (problem_.liquidFace[f] <= 0.0 || problem_.fluidFaceWeight(f) <= 0.0) continue;
        if (!havePhiG) {
          phiG = solids.phi(L.samplePosition(s, sparse_grid::faceMask(a)));
          havePhiG = true;
        }
        const double phiF = solids.phi(L.samplePosition(std::size_t(t), sparse_grid::faceMask(a)));
        if (!(phiF > 0.0) || phiF - phiG <= 0.0) continue;
        const double theta = std::max(phiF / (phiF - phiG), 0.25);
        const double us = problem_.solidVelocity(std::size_t(i));
        sum += theta * (us + (us - velocity_[f]) * (1.0 - theta) / theta);
        weights += theta;
      }
    if (weights > 0.0) ghost[i] = sum / weights;
  }
  velocity_.swap(ghost);
}

}  // namespace step
}  // namespace stokes::sim
