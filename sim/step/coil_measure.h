#pragma once
// Coil measure for the liquid rope coiling scene (thesis 5.1): the angle swept around the stream
// axis by the point where the falling rope meets the liquid already laid down, accumulated over
// time (unwrapped), so steady coiling in one direction grows it linearly.
//
// The contact point of a step: among the particles still falling along the stream axis faster
// than half the nozzle speed (v . a > speed / 2, with a the unit axis pointing from the nozzle
// downstream), the lowest ones -- within `slab` of the furthest downstream of them -- are the
// rope's end where it lands; their centroid, minus its component along the axis, is the contact
// offset r. Its angle atan2(r . e2, r . e1) in a fixed frame (e1, e2) across the axis is unwrapped
// against the previous step's (increments taken in (-180, 180] degrees). While the offset is
// shorter than `minRadius` (the rope lands on the axis: no coiling yet) or no particle qualifies,
// the angle is not updated.
#include <cmath>
#include <cstdint>
#include <limits>

#include "sim/particles/particles.h"

namespace stokes::sim {
inline namespace step {

class CoilMeasure {
 public:
  /// `axisPoint` / `axisDirection`: the nozzle centre and the stream direction (normalised here);
  /// `streamSpeed` the nozzle speed (> 0); `slab` and `minRadius` in world units.
  CoilMeasure(const Vec3d& axisPoint, const Vec3d& axisDirection, double streamSpeed, double slab, double minRadius);

  /// Updates the measure from the particles after a step; `overRanks`: each rank holds a part of
  /// them (a run split over ranks), and the deepest point, the centroid and the count are taken
  /// over all ranks, the centroid's sums exact (collective).
  void update(const ParticleSet<3>& particles, bool overRanks = false);

  /// Accumulated (unwrapped) swept angle in degrees; 0 until the first contact off the axis.
  double sweptDegrees() const { return swept_; }
  /// Distance of the last contact point from the axis (NaN before the first one).
  double radius() const { return radius_; }
  /// Particles in the last contact region.
  std::size_t contactParticles() const { return contact_; }

  /// What update() carries from step to step (a checkpoint's part; sim/run/checkpoint.h).
  struct State {
    double swept = 0.0, lastAngle = 0.0, radius = 0.0;
    std::uint64_t contact = 0;
  };
  State state() const { return {swept_, lastAngle_, radius_, contact_}; }
  void restore(const State& s) {
    swept_ = s.swept;
    lastAngle_ = s.lastAngle;
    radius_ = s.radius;
    contact_ = std::size_t(s.contact);
  }

 private:
  Vec3d point_, axis_, e1_, e2_;
  double speed_, slab_, minRadius_;
  double swept_ = 0.0, lastAngle_ = std::numeric_limits<double>::quiet_NaN();
  double radius_ = std::numeric_limits<double>::quiet_NaN();
  std::size_t contact_ = 0;
};

}  // namespace step
}  // namespace stokes::sim
