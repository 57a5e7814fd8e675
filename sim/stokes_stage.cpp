// The grid side of one simulation step: see stokes_stage.h.
#include "sim/stokes_stage.h"

#include <openvdb/tools/Morphology.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <limits>

#include "sim/apic_transfer.h"
#include "sim/grid_velocity.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::sim {

namespace {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

solver::PreconditionerKind preconditionerKind(PreconditionerType p) {
  switch (p) {
    case PreconditionerType::None: return solver::PreconditionerKind::None;
    case PreconditionerType::Multigrid: return solver::PreconditionerKind::Multigrid;
    default: return solver::PreconditionerKind::Jacobi;
  }
}

solver::TileCacheStrategy cacheStrategy(TileCache c) {
  switch (c) {
    case TileCache::None: return solver::TileCacheStrategy::None;
    case TileCache::Shapes: return solver::TileCacheStrategy::Shapes;
    default: return solver::TileCacheStrategy::Library;
  }
}

/// Reduced tiles of an affine / quadratic model (divergence-free basis; the decoupled viscosity
/// solve switches to the full basis, DESIGN.md §3). Quadratic tiles fit on all their faces, affine
/// ones on their boundary (NOTES.md §3). band_air >= 1 keeps tiles off the walls (stokes_stage.h).
std::optional<solver::ReducedOptions> reducedOptions(const ModelDesc& m, std::shared_ptr<solver::TileLibrary> library) {
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
  r.cache = cacheStrategy(m.tileCache);
  r.library = std::move(library);
  return r;
}

bool outsideDomain(const openvdb::Coord& c, const DomainBox& d) {
  for (int b = 0; b < kSimDim; ++b) {
    if (c[b] < 0) return true;
    if (c[b] >= d.cells[b] && !(b == 1 && d.openTop)) return true;
  }
  return false;
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
  Vec3d hi = max;
  if (openTop) hi[1] = std::numeric_limits<double>::max();
  return boxSignedDistance(x, min, hi);
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
  openvdb::CoordBBox clip = domain.cellBBox();
  if (domain.openTop) clip.max()[1] += band;  // air cells above an open top
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

StokesPlan planStokes(const Scene& scene, std::shared_ptr<solver::TileLibrary> library) {
  StokesPlan plan;
  if (!scene.hasViscosity()) plan.kind = StokesPlan::Kind::Projection;
  else if (scene.viscosity == ViscosityMode::Decoupled) plan.kind = StokesPlan::Kind::Decoupled;
  else plan.kind = StokesPlan::Kind::Coupled;
  solver::StepOptions& o = plan.options;
  switch (plan.kind) {
    case StokesPlan::Kind::Coupled: o.system = solver::SystemKind::UnifiedStokes; break;
    case StokesPlan::Kind::Decoupled: o.system = solver::SystemKind::Viscosity; break;
    default: o.system = solver::SystemKind::PressureProjection;
  }
  o.method = solver::KrylovMethod::CG;
  o.preconditioner = preconditionerKind(scene.solver.preconditioner);
  if (plan.kind == StokesPlan::Kind::Coupled && o.preconditioner == solver::PreconditionerKind::Multigrid) {
    // The V-cycle pays on the pressure-velocity form (block preconditioner, MINRES); on the SPD
    // pressure-stress form it saves only 2-3x (bench/results/preconditioners.md).
    o.form = solver::StokesForm::PressureVelocity;
    o.method = solver::KrylovMethod::MINRES;
  }
  o.krylov.relativeTolerance = scene.solver.tolerance;
  o.krylov.maxIterations = scene.solver.maxIterations;
  o.reduced = reducedOptions(scene.model, std::move(library));
  return plan;
}

GridStep::GridStep(const std::vector<Vec3d>& positions, const openvdb::FloatGrid& liquid, const ShapeField* solids,
                   const DomainBox& domain, const Scene& scene, double dt, bool needStressWeights, int band)
    : domain_(domain) {
  auto t0 = std::chrono::steady_clock::now();
  layout_ = std::make_unique<Layout3>(particleBandMask(positions, domain, band), domain.dx, domain.min);
  problem_.layout = layout_.get();
  problem_.rho = scene.material.density;
  problem_.mu = scene.hasViscosity() ? scene.material.viscosity : 0.0;
  problem_.dt = dt;
  problem_.allocate(/*withSolids=*/solids != nullptr);
  problem_.closedFace = closedWallFaces(*layout_, domain);
  for (std::size_t s = 0; s < layout_->numSlots(); ++s) report_.cells += layout_->isActiveCell(s) ? 1 : 0;
  report_.layoutSeconds = secondsSince(t0);
  report_.stages.push_back("layout");

  t0 = std::chrono::steady_clock::now();
  fillWeights(liquid, solids, needStressWeights);
  report_.weightSeconds = secondsSince(t0);
  report_.stages.push_back("weights");
}

void GridStep::fillWeights(const openvdb::FloatGrid& liquid, const ShapeField* solids, bool needStressWeights) {
  const Layout3& L = *layout_;
  const std::size_t n = L.numSlots();
  const GridPhi liquidPhi(liquid.copy());
  // The liquid extended into the solids it touches (thesis 3.6.4, Fig. 3.4c), and likewise into
  // the domain walls, whose solid is the outside of the box (phi = -phi_box): a wall's edge and
  // face samples then have their full liquid weight, so the wall holds the liquid as a solid does
  // (clipped to the box instead, they had half, and a layer sheared against the floor slipped by
  // about 3 dx).
  const double reach = kSolidExtensionCells * domain_.dx;
  auto phi = [&](const Vec3d& x) {
    const double phiL = liquidPhi(x);
    // Farther than 2 reach from the liquid the extension cannot change the sign: skip phi_S there.
    const double extended = solids && phiL < 2.0 * reach ? extendIntoSolid(phiL, solids->phi(x), reach) : phiL;
    return extendIntoSolid(extended, -domain_.phi(x), reach);
  };
  for (int a = 0; a < kSimDim; ++a)
    grid::computeVolumeFractionsOfDistance<kSimDim>(L, grid::faceMask(a), phi, problem_.liquidFace.data() + a * n);
  grid::computeVolumeFractionsOfDistance<kSimDim>(L, grid::kCellCentre, phi, problem_.liquidCell.data());
  if (needStressWeights)
    for (int c = 0; c < grid::StressChannels<kSimDim>::kCount; ++c)
      grid::computeVolumeFractionsOfDistance<kSimDim>(L, grid::StressChannels<kSimDim>::mask(c), phi,
                                            problem_.liquidStress.data() + c * n);
  if (!solids) return;
  // W_F = fraction outside the solids: the region where -phi_solid < 0.
  auto fluidPhi = [&](const Vec3d& x) { return -solids->phi(x); };
  for (int a = 0; a < kSimDim; ++a)
    grid::computeVolumeFractionsOfDistance<kSimDim>(L, grid::faceMask(a), fluidPhi, problem_.fluidFace.data() + a * n);
  for (int c = 0; c < grid::StressChannels<kSimDim>::kCount; ++c)
    grid::computeVolumeFractionsOfDistance<kSimDim>(L, grid::StressChannels<kSimDim>::mask(c), fluidPhi,
                                          problem_.fluidStress.data() + c * n);
  report_.builtFluidWeights = true;
  if (solids->moving()) fillSolidVelocity(*solids);
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
      problem_.uSolid[i] = solids.velocityAt(L.samplePosition(std::size_t(s), grid::faceMask(a)))[a];
    }
}

std::string GridStep::faceName(std::size_t i) const {
  const std::size_t n = layout_->numSlots();
  const openvdb::Coord c = layout_->cellOf(i % n);
  static const char* axes = "xyz";
  return std::string("face ") + axes[i / n] + " of cell (" + std::to_string(c.x()) + "," + std::to_string(c.y()) +
         "," + std::to_string(c.z()) + ")";
}

void GridStep::solve(const ParticleSet<kSimDim>& particles, const Vec3d* gravity, const StokesPlan& plan) {
  const std::size_t m = kSimDim * layout_->numSlots();
  auto t0 = std::chrono::steady_clock::now();
  particlesToGrid<kSimDim>(*layout_, particles, problem_.uStar, faceMass_);
  for (std::size_t i = 0; i < m; ++i)
    if (problem_.closedFace[i]) problem_.uStar[i] = 0.0;
  report_.p2gSeconds = secondsSince(t0);
  report_.stages.push_back("p2g");

  if (gravity) {
    // u* += g dt on every open face (thesis Algorithm 1: body forces before the Stokes step)
    t0 = std::chrono::steady_clock::now();
    const std::size_t n = layout_->numSlots();
    for (std::size_t i = 0; i < m; ++i)
      if (!problem_.closedFace[i]) problem_.uStar[i] += (*gravity)[int(i / n)] * problem_.dt;
    report_.gravitySeconds = secondsSince(t0);
    report_.stages.push_back("gravity");
  }
  for (std::size_t i = 0; i < m; ++i)
    if (!std::isfinite(problem_.uStar[i]))
      throw SimulationError("stage p2g: non-finite velocity u* on " + faceName(i));

  switch (plan.kind) {
    case StokesPlan::Kind::Coupled: {
      runSolve("stokes", plan.options, report_.stokesSeconds);
      for (double w : problem_.liquidStress) report_.stressUnknowns += w > 0.0 ? 1 : 0;
      break;
    }
    case StokesPlan::Kind::Decoupled: {
      // viscosity (full basis on tiles: its input is not divergence-free), then the projection
      solver::StepOptions visc = plan.options;
      visc.system = solver::SystemKind::Viscosity;
      if (visc.reduced) visc.reduced->family = solver::BasisFamily::Full;
      runSolve("viscosity", visc, report_.viscositySeconds);
      problem_.uStar = velocity_;
      solver::StepOptions proj = plan.options;
      proj.system = solver::SystemKind::PressureProjection;
      runSolve("pressure", proj, report_.pressureSeconds);
      break;
    }
    default: {
      solver::StepOptions proj = plan.options;
      proj.system = solver::SystemKind::PressureProjection;
      runSolve("pressure", proj, report_.pressureSeconds);
    }
  }
  extrapolate(3);
  report_.stages.push_back("extrapolate");
}

void GridStep::runSolve(const char* stage, const solver::StepOptions& options, double& seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  solver::StepReport rep;
  try {
    rep = solver::solveStep(problem_, options, velocity_);
  } catch (const std::invalid_argument& e) {
    throw SimulationError(std::string("stage ") + stage + ": " + e.what());
  }
  seconds = secondsSince(t0);
  report_.stages.push_back(stage);
  report_.iterations += rep.solve.iterations;
  report_.unknowns += rep.unknowns;
  report_.tiles += rep.tiles;
  report_.fallbackTiles += rep.fallbackTiles;
  report_.relativeResidual = std::max(report_.relativeResidual, rep.solve.relativeResidual);
  if (!rep.solve.converged())
    throw SimulationError(std::string("stage ") + stage + ": the " + solver::toString(options.system) +
                          " solve did not converge (status " + solver::toString(rep.solve.status) + " after " +
                          std::to_string(rep.solve.iterations) + " iterations, relative residual " +
                          std::to_string(rep.solve.relativeResidual) + ", tolerance " +
                          std::to_string(options.krylov.relativeTolerance) + ", " +
                          std::to_string(rep.unknowns) + " unknowns; " + rep.diagnostics + ")");
  // tiles that fell back to Cartesian cells: named once per step (the step itself is fine)
  if (rep.fallbackTiles > 0) std::fprintf(stderr, "[stokesvdb] stage %s: %s\n", stage, rep.diagnostics.c_str());
  for (std::size_t i = 0; i < velocity_.size(); ++i)
    if (!std::isfinite(velocity_[i]))
      throw SimulationError(std::string("stage ") + stage + ": non-finite velocity on " + faceName(i));
}

void GridStep::extrapolate(int layers) {
  // Faces that hold liquid (solved), lie on a wall or inside a solid (W_F = 0: the solid's
  // velocity) are known; the rest take the mean of their known neighbours, layer by layer, so G2P
  // and advection near the surface read liquid velocities. A solid face must stay known: filled
  // with the liquid's velocity it lets G2P and advection slide particles along the solid, undoing
  // the no-slip the solve imposed (the beam slid off its block this way).
  const std::size_t m = velocity_.size();
  std::vector<std::uint8_t> known(m);
  for (std::size_t i = 0; i < m; ++i)
    known[i] = (problem_.liquidFace[i] > 0.0 || problem_.closedFace[i] || problem_.fluidFaceWeight(i) <= 0.0) ? 1 : 0;
  extrapolateFaceVelocities<kSimDim>(*layout_, velocity_, known, layers);
}

}  // namespace stokes::sim
