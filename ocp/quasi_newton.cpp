// Dense quasi-Newton blocks of the Lagrangian's Hessian (quasi_newton.hpp).
#include "quasi_newton.hpp"

#include <cmath>

namespace moreau::ocp_internal {

namespace {
// Steps shorter than this (relative to 1 + |B|) carry no curvature information above
// round-off: skipped.
constexpr double kSmallestStep = 1e-14;
// Powell's damping threshold: s^T y >= 0.2 s^T B s after damping (Nocedal and Wright, 18.2).
constexpr double kPowellDamping = 0.2;
// SR1 skip rule: |s^T r| >= kSr1Skip |s| |r| (Nocedal and Wright, 6.26).
constexpr double kSr1Skip = 1e-8;
}  // namespace

QuasiNewtonBlock::QuasiNewtonBlock(int size, Kind kind, int memory) : kind_(kind), memory_(memory) {
  b_ = Matrix::Identity(size, size);
}

void QuasiNewtonBlock::Reset() {
  b_.setIdentity();
  scaled_ = false;
  pairs_.clear();
}

bool QuasiNewtonBlock::Update(const Vector& s, const Vector& y) {
  if (s.size() == 0 || !s.allFinite() || !y.allFinite()) return false;
  if (s.norm() <= kSmallestStep) return false;
  if (memory_ <= 0) return Apply(s, y);
  pairs_.emplace_back(s, y);
  while (static_cast<int>(pairs_.size()) > memory_) pairs_.pop_front();
  // Rebuild on the scaling of the newest pair with positive curvature.
  b_.setIdentity();
  scaled_ = false;
  for (auto it = pairs_.rbegin(); it != pairs_.rend(); ++it) {
    const double sy = it->first.dot(it->second);
    if (sy > 0.0) {
      b_ *= it->second.squaredNorm() / sy;
      scaled_ = true;
      break;
    }
  }
  bool any = false;
  for (const auto& [step, change] : pairs_) any = Apply(step, change) || any;
  return any;
}

bool QuasiNewtonBlock::Apply(const Vector& s, const Vector& y) {
  const double sy = s.dot(y);
  if (!scaled_ && sy > 0.0) {
    // Initial scaling: the identity times the curvature along the first step.
    b_ = Matrix::Identity(size(), size()) * (y.squaredNorm() / sy);
    scaled_ = true;
  }
  const Vector bs = b_ * s;
  const double sbs = s.dot(bs);
  Matrix next;
  if (kind_ == Kind::kDampedBfgs) {
    if (!(sbs > 0.0)) return false;
    Vector r = y;
    if (sy < kPowellDamping * sbs) {
      const double theta = (1.0 - kPowellDamping) * sbs / (sbs - sy);
      r = theta * y + (1.0 - theta) * bs;
    }
    const double sr = s.dot(r);
    if (!(sr > 0.0)) return false;
    next = b_ + r * r.transpose() / sr - bs * bs.transpose() / sbs;
  } else {
    const Vector r = y - bs;
    const double sr = s.dot(r);
    if (std::fabs(sr) < kSr1Skip * s.norm() * r.norm() || sr == 0.0) return false;
    next = b_ + r * r.transpose() / sr;
  }
  if (!next.allFinite()) return false;
  b_ = 0.5 * (next + next.transpose());  // symmetric to round-off
  return true;
}

}  // namespace moreau::ocp_internal
