#include "group_system.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "moreau/core/error.hpp"

namespace moreau::internal {

GroupSystem::GroupSystem(LoweredSystem* system, int stages)
    : system_(system),
      s_(stages),
      ny_(system->num_states()),
      nz_(system->num_algebraic()),
      ng_(system->num_equations()),
      np_(system->num_pairs()) {
  element_size_ = s_ * (ny_ + nz_);
  element_rows_ = s_ * (ny_ + ng_ + np_);
  MOREAU_ASSERT(element_size_ == element_rows_, "FESD element system is not square");
}

void GroupSystem::Resize() {
  nz_ = system_->num_algebraic();
  ng_ = system_->num_equations();
  np_ = system_->num_pairs();
  element_size_ = s_ * (ny_ + nz_);
  element_rows_ = s_ * (ny_ + ng_ + np_);
  MOREAU_ASSERT(element_size_ == element_rows_, "FESD element system is not square");
  elements_.clear();
  value_elements_.clear();
}

void GroupSystem::Configure(const GroupSetup& setup) {
  MOREAU_ASSERT(setup.elements >= 1, "a group needs at least one element");
  MOREAU_ASSERT(static_cast<int>(setup.a_zero.size()) == np_, "wrong number of statuses");
  setup_ = setup;
  // The velocity level's roles of the group's statuses (LoweredSystem::RolesFor, kept).
  velocity_roles_.resize(setup.a_zero.size());
  for (std::size_t k = 0; k < setup.a_zero.size(); ++k) {
    velocity_roles_[k] = setup.a_zero[k] ? PairRole::kAZero : PairRole::kBZero;
  }
  while (static_cast<int>(elements_.size()) < setup.elements) {
    elements_.emplace_back(system_, s_);
    value_elements_.emplace_back(system_, s_);
  }
  if (setup.with_event && nz_ > 0) {
    // Every row by the size of its terms at y_start: its value at v = 0 and its change to the
    // consistent guess (|q| + |M v0| for a row M v + q; Stewart's rates are theta times the
    // mode fields, zero at v = 0). Rates of the continuous sides and of the equations are of
    // the size of the rates of the model, which a fast time scale (circuits in seconds, a
    // switching function that changes by 1 in a microsecond: rates of 1e5 and more) makes too
    // large for an absolute 1e-12: their round-off exceeds it, the group's Newton cannot
    // converge and the switch is not located. Relative to the data the rows keep their
    // accuracy: a row scaled by 1 / max(1, size) determines v to 1e-12 max(1, size) / |M|, of
    // the size of v itself.
    velocity_scale_.setOnes(nz_);
    const std::vector<PairRole> roles = LoweredSystem::RolesFor(setup.a_zero);
    VelocityLevelEvaluation free, guessed;
    system_->EvaluateVelocityLevel(setup.y_start, Vector::Zero(nz_), roles, Derivatives::kNone,
                                   &free);
    system_->InitialAlgebraicGuess(setup.y_start, nullptr, &scale_guess_);
    system_->EvaluateVelocityLevel(setup.y_start, scale_guess_, roles, Derivatives::kNone,
                                   &guessed);
    const Eigen::Index rows = std::min<Eigen::Index>(nz_, free.equations.size());
    for (Eigen::Index r = 0; r < rows; ++r) {
      const double size =
          std::fabs(free.equations[r]) + std::fabs(guessed.equations[r] - free.equations[r]);
      if (std::isfinite(size)) velocity_scale_[r] = 1.0 / std::max(1.0, size);
    }
  }
  da_status_.resize(s_ * np_);
  db_status_.resize(s_ * np_);
  for (int i = 0; i < s_; ++i) {
    for (int k = 0; k < np_; ++k) {
      const bool a_zero = setup.a_zero[static_cast<std::size_t>(k)];
      da_status_[i * np_ + k] = a_zero ? 1.0 : 0.0;
      db_status_[i * np_ + k] = a_zero ? 0.0 : 1.0;
    }
  }
}

int GroupSystem::num_unknowns() const {
  return setup_.elements * element_size_ + (setup_.with_event ? nz_ + 1 : 0);
}

int GroupSystem::num_equations() const {
  return setup_.elements * element_rows_ + (setup_.with_event ? nz_ : 0);
}

double GroupSystem::EstimatedJacobianNonzeros() const {
  const double n = num_unknowns();
  if (!system_->sparse()) return n * n;
  // Elements, the coupling of every element to the ends of the earlier ones, and with an
  // event the velocity-level rows at the end state (their y-part once per element: the end
  // state is the sum of the elements' last increments; products like A_y F_z give about
  // twice the entries of their factors) and the event row.
  const double m = setup_.elements;
  const CollocationStages& stages = elements_.front();
  const LoweredSystem::Nonzeros& nz = system_->nonzeros();
  double estimate =
      m * stages.EstimatedJacobianNonzeros() + m * (m - 1) / 2 * stages.EstimatedStartNonzeros();
  if (setup_.with_event) {
    estimate +=
        2.0 * (m * (nz.A_y + nz.B_y + nz.G_y + nz.F_y) + nz.A_z + nz.B_z + nz.G_z + nz.F_z) +
        m * ny_ + nz_ + 1.0;
  }
  return estimate;
}

Vector GroupSystem::ElementStart(const ConstVectorRef& w, int e) const {
  Vector y;
  ElementStart(w, e, &y);
  return y;
}

void GroupSystem::ElementStart(const ConstVectorRef& w, int e, Vector* y) const {
  *y = setup_.y_start;
  const int last = (s_ - 1) * (ny_ + nz_);
  for (int k = 0; k < e; ++k) *y += w.segment(element_offset(k) + last, ny_);
}

Vector GroupSystem::EndState(const ConstVectorRef& w) const {
  return ElementStart(w, setup_.elements);
}

void GroupSystem::EndState(const ConstVectorRef& w, Vector* y) const {
  ElementStart(w, setup_.elements, y);
}

void GroupSystem::EvaluateAll(const Vector& w, Derivatives derivatives,
                              std::vector<CollocationStages>* target) {
  start_scratch_ = setup_.y_start;
  const int last = (s_ - 1) * (ny_ + nz_);
  for (int e = 0; e < setup_.elements; ++e) {
    const auto w_e = w.segment(element_offset(e), element_size_);
    (*target)[static_cast<std::size_t>(e)].Evaluate(start_scratch_, w_e, derivatives);
    start_scratch_ += w_e.segment(last, ny_);  // the next element starts at this one's end
  }
}

bool GroupSystem::Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) {
  const double h = H(w);
  if (!(h > 0.0) || !std::isfinite(h)) return false;  // element lengths must stay positive
  std::vector<CollocationStages>& target = with_jacobian ? elements_ : value_elements_;
  last_with_jacobian_ = with_jacobian;
  if (with_jacobian) h_jacobian_ = h;
  const Derivatives with = parameter_derivatives_ ? Derivatives::kAll : Derivatives::kStates;
  EvaluateAll(w, with_jacobian ? with : Derivatives::kNone, &target);
  r->resize(num_equations());
  pair_a_.resize(s_ * np_);
  pair_b_.resize(s_ * np_);
  Vector& pair_a = pair_a_;
  Vector& pair_b = pair_b_;
  for (int e = 0; e < setup_.elements; ++e) {
    const int row0 = e * element_rows_;
    const int equations = s_ * (ny_ + ng_);
    const CollocationStages& stages = target[static_cast<std::size_t>(e)];
    stages.Residual(h, w.segment(element_offset(e), element_size_), r->segment(row0, equations),
                    pair_a, pair_b);
    // Status equations: the side that the group's status keeps at zero, at every stage.
    r->segment(row0 + equations, s_ * np_) =
        da_status_.cwiseProduct(pair_a) + db_status_.cwiseProduct(pair_b);
  }
  a->resize(num_pairs());
  b->resize(num_pairs());
  if (setup_.with_event) {
    Vector& y_end = end_scratch_;
    EndState(w, &y_end);
    const auto v = w.segment(v_offset(), nz_);
    const Derivatives level = with_jacobian ? with : Derivatives::kNone;
    // Into the members that AssembleJacobian reads (with derivatives) or into scratch (values
    // for the line search), so that no evaluation allocates.
    VelocityLevelEvaluation& velocity = with_jacobian ? velocity_ : value_velocity_;
    IndicatorEvaluation& indicators = with_jacobian ? indicators_ : value_indicators_;
    system_->EvaluateVelocityLevel(y_end, v, velocity_roles_, level, &velocity);
    system_->EvaluateEventIndicators(y_end, v, setup_.a_zero, level, &indicators);
    // (velocity level) consistent multipliers at the group's end state.
    r->segment(setup_.elements * element_rows_, nz_) = velocity.equations;
    // (element-length complementarity) 0 <= (h_max - h)/h_max ⟂ min_k scaled iota_k >= 0.
    const double tau = h / setup_.h_reference;
    int best = -1;
    double smallest = std::numeric_limits<double>::infinity();
    for (int k = 0; k < np_; ++k) {
      const double scaled = setup_.indicator_weights[k] * indicators.values[k] /
                            std::pow(tau, setup_.indicator_power[static_cast<std::size_t>(k)]);
      if (scaled < smallest) {
        smallest = scaled;
        best = k;
      }
    }
    (*a)[0] = (setup_.h_max - h) / setup_.h_max;
    (*b)[0] = best >= 0 ? smallest : 1.0;
    if (with_jacobian) {
      event_b_ = (*b)[0];
      event_pair_ = best;
      tau_ = tau;
    }
  }
  return r->allFinite() && a->allFinite() && b->allFinite();
}

void GroupSystem::AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) {
  const int m = setup_.elements;
  const int last = (s_ - 1) * (ny_ + nz_);
  const int equations = s_ * (ny_ + ng_);
  const double h = h_jacobian_;  // h of the last with-Jacobian evaluation
  for (int e = 0; e < m; ++e) {
    const int row0 = e * element_rows_;
    const CollocationStages& stages = elements_[static_cast<std::size_t>(e)];
    stages.AddJacobian(h, da_status_, db_status_, row0, row0 + equations, element_offset(e),
                       jacobian);
    // Element e starts where element e' < e ended: y_e0 depends on every earlier Z_{e', s}.
    for (int k = 0; k < e; ++k) {
      stages.AddStartJacobian(h, da_status_, db_status_, row0, row0 + equations,
                              element_offset(k) + last, jacobian);
    }
    if (setup_.with_event) {
      const Vector dh = stages.ResidualDerivativeH();
      for (int i = 0; i < equations; ++i) {
        if (dh[i] != 0.0) jacobian->AddEntry(row0 + i, h_index(), dh[i]);
      }
    }
  }
  if (!setup_.with_event) return;
  const int velocity_row = m * element_rows_;
  jacobian->AddDerivative(velocity_row, v_offset(), velocity_.equations_v);
  for (int e = 0; e < m; ++e) {
    jacobian->AddDerivative(velocity_row, element_offset(e) + last, velocity_.equations_y);
  }
  const int event_row = num_equations();
  jacobian->AddEntry(event_row, h_index(), da[0] * (-1.0 / setup_.h_max));
  if (event_pair_ >= 0) {
    const int k = event_pair_;
    const int power = setup_.indicator_power[static_cast<std::size_t>(k)];
    const double weight = setup_.indicator_weights[k] / std::pow(tau_, power);
    // Row k of the indicator derivatives (the smallest indicator) only: its entries stay in
    // the pattern while k is the minimum (db = 0 included), and the event row stays sparse.
    const double row_weight = db[0] * weight;
    for (int e = 0; e < m; ++e) {
      jacobian->AddScaledRow(event_row, element_offset(e) + last, k, row_weight, indicators_.d_y);
    }
    jacobian->AddScaledRow(event_row, v_offset(), k, row_weight, indicators_.d_v);
    if (power > 0) {
      // d/dh of iota / tau^p with tau = h / h_ref.
      const double d_tau = -power * weight * indicators_.values[k] / tau_ / setup_.h_reference;
      jacobian->AddEntry(event_row, h_index(), db[0] * d_tau);
    }
  }
}

void GroupSystem::ResidualScale(const Vector& /*w*/, Vector* scale) {
  scale->setOnes(num_unknowns());
  for (int e = 0; e < setup_.elements; ++e) {
    for (int i = 0; i < s_; ++i) {
      for (int k = 0; k < ny_; ++k) {
        (*scale)[e * element_rows_ + i * (ny_ + ng_) + k] =
            1.0 / (1.0 + std::fabs(setup_.y_start[k]));
      }
    }
  }
  if (setup_.with_event && nz_ > 0) {
    scale->segment(setup_.elements * element_rows_, nz_) = velocity_scale_;
  }
}

void GroupSystem::EvaluateForSensitivities(const Vector& w) {
  EvaluateAll(w, Derivatives::kAll, &elements_);
  last_with_jacobian_ = true;
  if (!setup_.with_event) return;
  const Vector y_end = EndState(w);
  const auto v = w.segment(v_offset(), nz_);
  system_->EvaluateVelocityLevel(y_end, v, LoweredSystem::RolesFor(setup_.a_zero),
                                 Derivatives::kAll, &velocity_);
  system_->EvaluateEventIndicators(y_end, v, setup_.a_zero, Derivatives::kAll, &indicators_);
}

void GroupSystem::SensitivityBlocks(const Vector& w, double event_da, double event_db,
                                    ParameterBlocks* out) const {
  const int rows = num_equations() + num_pairs();
  const int nu = system_->num_inputs(), np = system_->num_parameters();
  const int equations = s_ * (ny_ + ng_);
  const double h = H(w);
  out->y_start.setZero(rows, ny_);
  out->p.setZero(rows, np);
  out->u.setZero(rows, nu);
  out->h_fixed.setZero(rows);
  out->h_max.setZero(rows);
  out->h_reference.setZero(rows);
  for (int e = 0; e < setup_.elements; ++e) {
    const int row0 = e * element_rows_;
    const CollocationStages& stages = elements_[static_cast<std::size_t>(e)];
    // Every element start is y_start plus earlier increments: d y_e0 / d y_start = I.
    SystemMatrix block;
    block.Reset(std::max(element_rows_, ny_), false);
    stages.AddStartJacobian(h, da_status_, db_status_, 0, equations, 0, &block);
    out->y_start.middleRows(row0, element_rows_) = block.dense().topLeftCorner(element_rows_, ny_);
    Matrix d_u, d_p;
    stages.ParameterJacobian(h, da_status_, db_status_, &d_u, &d_p);
    out->u.middleRows(row0, element_rows_) = d_u;
    out->p.middleRows(row0, element_rows_) = d_p;
    if (!setup_.with_event) out->h_fixed.segment(row0, equations) = stages.ResidualDerivativeH();
  }
  if (!setup_.with_event) return;
  const int velocity_row = setup_.elements * element_rows_;
  out->y_start.middleRows(velocity_row, nz_) = velocity_.equations_y.ToDense();
  out->u.middleRows(velocity_row, nz_) = velocity_.equations_u.ToDense();
  out->p.middleRows(velocity_row, nz_) = velocity_.equations_p.ToDense();
  const int event_row = num_equations();
  out->h_max[event_row] = event_da * h / (setup_.h_max * setup_.h_max);
  if (event_pair_ >= 0) {
    const int k = event_pair_;
    const int power = setup_.indicator_power[static_cast<std::size_t>(k)];
    const double weight = setup_.indicator_weights[k] / std::pow(tau_, power);
    out->y_start.row(event_row) = event_db * weight * indicators_.d_y.Row(k);
    out->u.row(event_row) = event_db * weight * indicators_.d_u.Row(k);
    out->p.row(event_row) = event_db * weight * indicators_.d_p.Row(k);
    if (power > 0) {
      // d/dh_ref of w iota (h_ref / h)^p = p w iota tau^{-p} / h_ref.
      out->h_reference[event_row] =
          event_db * power * weight * indicators_.values[k] / setup_.h_reference;
    }
  }
}

}  // namespace moreau::internal
