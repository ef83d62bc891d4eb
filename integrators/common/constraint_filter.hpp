#pragma once
// The near-active constraint filter (docs/sparse-systems.md, "Near-active constraints"),
// shared by FESD and the time-stepping baseline. Private to moreau::integrators.
//
// At the start of every step the integrator asks for a working set: the moving-set
// constraints that may come into contact within the step stay in the lowered system, the
// others are left out (lambda = 0, no pair, unknown or equation). A constraint k is kept if
//   c_k(y) <= margin_k = safety * H * r_k + kMarginFloor,
//   r_k = |grad_x c_k(y)|_1 max_i |x_i'| + |dc_k/dt|   (a bound on its rate at the step start),
// or if it is active (its status keeps c_k = 0, or its multiplier is positive), or if it was
// in the working set and c_k <= 2 margin_k (hysteresis: the set does not flicker). The rate
// bound is taken at the step start, so it is not a proof: every solved element is checked
// afterwards (Check at its stage points), and a left-out constraint that is not positive there
// joins the working set and the step is solved again. The certificates of the elements (and
// the tests) cover every declared constraint.

#include <vector>

#include "moreau/model/lowered_system.hpp"

namespace moreau::internal {

class NearActiveFilter {
 public:
  // Constraints at or below this value are always kept (round-off of a contact).
  static constexpr double kMarginFloor = 1e-9;

  NearActiveFilter(LoweredSystem* system, ConstraintFilter mode, double safety);

  bool enabled() const { return enabled_; }
  // Chooses the working set for a step of length `horizon` from state y, with the current
  // statuses `a_zero` and algebraic values `z` (in the current layout; empty before the first
  // status decision). Returns true if the working set changed; *previous then holds the layout
  // the integrator's state is in (LoweredSystem::Remap*).
  bool Update(const Vector& y, const std::vector<bool>& a_zero, const Vector& z, double horizon,
              LoweredSystem::WorkingLayout* previous);
  // True if every left-out constraint is positive at y; otherwise they are marked to join the
  // working set at the next Update (the caller solves the step again). *smallest: the
  // smallest left-out constraint at y (infinity if none). A marked constraint stays in the
  // working set until StepAccepted: otherwise the hysteresis test could drop it again at the
  // retry's Update (its value at the step start far above the margin) and the step would be
  // solved again and again without it.
  bool Check(const Vector& y, double* smallest);
  // The step was accepted: constraints marked by Check are filtered by the margin again.
  void StepAccepted();
  // The working set as flags over the declared pairs (snapshots), and its restoration.
  std::vector<bool> working() const;
  // The same into *flags (a kept snapshot's vector: no allocation per step).
  void working(std::vector<bool>* flags) const;
  bool Restore(const std::vector<bool>& working, LoweredSystem::WorkingLayout* previous);

  struct Stats {
    long updates = 0;   // working-set choices
    long changes = 0;   // choices that changed the working set
    long rechecks = 0;  // steps solved again because a left-out constraint was not positive
    int max_working = 0;
  };
  const Stats& stats() const { return stats_; }

 private:
  LoweredSystem* system_;
  double safety_;
  bool enabled_ = false;
  std::vector<bool> forced_;                   // declared pairs that must join at the next Update
  std::vector<bool> keep_, working_, active_;  // Update's flags over the declared pairs
  Vector values_, rates_;
  PointEvaluation point_;
  Vector zero_z_;    // Update: z = 0 where the given z does not fit
  Vector velocity_;  // Update: the scene states' velocities
  Stats stats_;
};

}  // namespace moreau::internal
