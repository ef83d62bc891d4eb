#include "constraint_filter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "moreau/core/error.hpp"
#include "moreau/integrators/working_set.hpp"

namespace moreau {
namespace {
thread_local long working_set_changes = 0;
}  // namespace

long WorkingSetChangesOnThisThread() { return working_set_changes; }

namespace internal {

NearActiveFilter::NearActiveFilter(LoweredSystem* system, ConstraintFilter mode, double safety)
    : system_(system), safety_(safety) {
  int filterable = 0;
  for (int k = 0; k < system->num_declared_pairs(); ++k) filterable += system->PairFilterable(k);
  enabled_ =
      filterable > 0 && (mode == ConstraintFilter::kOn ||
                         (mode == ConstraintFilter::kAutomatic && filterable > kFilterThreshold));
  forced_.assign(static_cast<std::size_t>(system->num_declared_pairs()), false);
}

bool NearActiveFilter::Update(const Vector& y, const std::vector<bool>& a_zero, const Vector& z,
                              double horizon, LoweredSystem::WorkingLayout* previous) {
  if (!enabled_) return false;
  ++stats_.updates;
  const int declared = system_->num_declared_pairs();
  // Velocities at the step start (multipliers included when known).
  // (z itself where it fits: no copy per step.)
  const Vector* z_point = &z;
  if (z.size() != system_->num_algebraic()) {
    zero_z_.setZero(system_->num_algebraic());
    z_point = &zero_z_;
  }
  system_->Evaluate(y, *z_point, Derivatives::kNone, &point_);
  velocity_ = point_.F.head(system_->num_scene_states());  // (kept: no temporary per step)
  system_->FilterableConstraints(y, velocity_, &values_, &rates_);
  // (Kept flag vectors: a step allocates nothing.)
  std::vector<bool>& keep = keep_;
  std::vector<bool>& working = working_;
  std::vector<bool>& active = active_;
  keep.assign(static_cast<std::size_t>(declared), true);
  working.assign(static_cast<std::size_t>(declared), false);
  active.assign(static_cast<std::size_t>(declared), false);
  const std::vector<int>& pairs = system_->working_pairs();
  for (std::size_t j = 0; j < pairs.size(); ++j) {
    const auto k = static_cast<std::size_t>(pairs[j]);
    working[k] = true;
    // Active: the status keeps c = 0 (a_zero: its first side, c, is zero) or lambda > 0.
    const bool kept_zero = j < a_zero.size() && a_zero[j];
    const bool pushing = static_cast<Eigen::Index>(j) < point_.B.size() && point_.B[j] > 0.0;
    active[k] = kept_zero || pushing;
  }
  for (int k = 0; k < declared; ++k) {
    const auto i = static_cast<std::size_t>(k);
    if (!system_->PairFilterable(k)) continue;
    const double margin = safety_ * horizon * rates_[k] + kMarginFloor;
    const double c = values_[k];
    keep[i] = forced_[i] || active[i] || !(c > margin) || (working[i] && !(c > 2.0 * margin));
  }
  // The same working set (most steps): nothing to set, and no layout to copy.
  const bool changed = keep != working;
  if (changed) {
    *previous = system_->working_layout();
    const bool set = system_->SetWorkingPairs(keep);
    MOREAU_ASSERT(set, "a different working set left the system unchanged");
    ++stats_.changes;
    ++working_set_changes;
  }
  stats_.max_working = std::max(stats_.max_working, system_->num_pairs());
  return changed;
}

bool NearActiveFilter::Check(const Vector& y, double* smallest) {
  *smallest = std::numeric_limits<double>::infinity();
  if (!enabled_ || system_->num_pairs() == system_->num_declared_pairs()) return true;
  *smallest = system_->MinExcludedConstraint(y);
  if (*smallest > 0.0) return true;
  // The rate bound missed them: they join, and the step is solved again.
  system_->ExcludedViolations(y, 0.0, &forced_);
  ++stats_.rechecks;
  return false;
}

void NearActiveFilter::StepAccepted() { std::fill(forced_.begin(), forced_.end(), false); }

std::vector<bool> NearActiveFilter::working() const {
  std::vector<bool> flags;
  working(&flags);
  return flags;
}

void NearActiveFilter::working(std::vector<bool>* flags) const {
  flags->assign(static_cast<std::size_t>(system_->num_declared_pairs()), false);
  for (int k : system_->working_pairs()) (*flags)[static_cast<std::size_t>(k)] = true;
}

bool NearActiveFilter::Restore(const std::vector<bool>& working,
                               LoweredSystem::WorkingLayout* previous) {
  if (!enabled_) return false;
  *previous = system_->working_layout();
  const bool changed = system_->SetWorkingPairs(working);
  if (changed) ++working_set_changes;
  return changed;
}

}  // namespace internal
}  // namespace moreau
