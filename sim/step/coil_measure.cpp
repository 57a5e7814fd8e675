// Coil measure: see coil_measure.h.
#include "sim/step/coil_measure.h"

#include "sim/ranks/exact_sum.h"
#include "sim/ranks/rank_comm.h"

#include <numbers>
#include <stdexcept>

namespace stokes::sim {
inline namespace step {

CoilMeasure::CoilMeasure(const Vec3d& axisPoint, const Vec3d& axisDirection, double streamSpeed, double slab,
                         double minRadius)
    : point_(axisPoint), speed_(streamSpeed), slab_(slab), minRadius_(minRadius) {
  if (!(axisDirection.length() > 0.0)) throw std::invalid_argument("CoilMeasure: zero axis direction");
  axis_ = axisDirection.unit();
  // e1: the world axis least aligned with the stream, made orthogonal to it; e2 = axis x e1
  Vec3d helper(1.0, 0.0, 0.0);
  if (std::abs(axis_.x()) > std::abs(axis_.z())) helper = Vec3d(0.0, 0.0, 1.0);
  e1_ = (helper - helper.dot(axis_) * axis_).unit();
  e2_ = axis_.cross(e1_);
}

void CoilMeasure::update(const ParticleSet<3>& particles, bool overRanks) {
  const double threshold = 0.5 * speed_;
  double deepest = -std::numeric_limits<double>::infinity();
  for (std::size_t p = 0; p < particles.size(); ++p)
    if (particles.v[p].dot(axis_) > threshold) deepest = std::max(deepest, (particles.x[p] - point_).dot(axis_));
  if (overRanks) deepest = maxOverRanks(deepest);
  contact_ = 0;
  if (!std::isfinite(deepest)) return;
  Vec3d sum(0.0);
  ExactSum exact[3];  // over ranks: the same bits for any rank count
  for (std::size_t p = 0; p < particles.size(); ++p) {
    const Vec3d d = particles.x[p] - point_;
    if (particles.v[p].dot(axis_) > threshold && d.dot(axis_) >= deepest - slab_) {
      if (overRanks)
        for (int a = 0; a < 3; ++a) exact[a].add(d[a]);
      else
        sum += d;
      ++contact_;
    }
  }
  if (overRanks) {
    contact_ = std::size_t(sumOverRanks(std::int64_t(contact_)));
    for (int a = 0; a < 3; ++a) sum[a] = exact[a].overRanks().value();
  }
  const Vec3d centroid = sum / double(contact_);
  const Vec3d offset = centroid - centroid.dot(axis_) * axis_;
  radius_ = offset.length();
  if (radius_ < minRadius_) return;
  const double angle = std::atan2(offset.dot(e2_), offset.dot(e1_)) * 180.0 / std::numbers::pi;
  if (std::isfinite(lastAngle_)) {
    double delta = angle - lastAngle_;
    while (delta > 180.0) delta -= 360.0;
    while (delta <= -180.0) delta += 360.0;
    swept_ += delta;
  }
  lastAngle_ = angle;
}

}  // namespace step
}  // namespace stokes::sim
