// The parameter blocks of a converged group system (GroupSystem::SensitivityBlocks) applied
// as products, forward and transposed, without forming them: directional and adjoint
// sensitivities of systems too large for dense n_rows x n_y blocks (docs/sensitivities.md).
// Every product follows SensitivityBlocks row block by row block; the two must stay in step.
#include <cmath>

#include "group_system.hpp"

namespace moreau::internal {
namespace {

// y += M x for an optional argument (n_p or n_u may be zero).
void MultiplyAddIf(const DerivativeMatrix& m, const ConstVectorRef& x, VectorRef y,
                   double scale = 1.0) {
  if (x.size() > 0 && m.cols() > 0) m.MultiplyAdd(x, y, scale);
}

void TransposedMultiplyAddIf(const DerivativeMatrix& m, const ConstVectorRef& x, VectorRef y,
                             double scale = 1.0) {
  if (y.size() > 0 && m.cols() > 0) m.TransposedMultiplyAdd(x, y, scale);
}

}  // namespace

void GroupSystem::AddBlockProduct(const Vector& w, double event_da, double event_db,
                                  const ConstVectorRef& dy, const ConstVectorRef& dp,
                                  const ConstVectorRef& du, const LengthChanges& dh,
                                  VectorRef rhs) const {
  const double h = H(w);
  const int equations = s_ * (ny_ + ng_);
  Vector field(ny_), pair(np_);
  for (int e = 0; e < setup_.elements; ++e) {
    const int row0 = e * element_rows_;
    const CollocationStages& stages = elements_[static_cast<std::size_t>(e)];
    const Matrix& a = stages.tableau().a;
    for (int j = 0; j < s_; ++j) {
      // (collocation) -h sum_j a_ij (F_y dy + F_p dp + F_u du)(Y_j), and with fixed lengths
      // -dh sum_j a_ij F(Y_j).
      const PointEvaluation& stage = stages.stage(j);
      field.setZero();
      stage.F_y.MultiplyAdd(dy, field);
      MultiplyAddIf(stage.F_p, dp, field);
      MultiplyAddIf(stage.F_u, du, field);
      if (!setup_.with_event) field += (dh.fixed / h) * stage.F;
      for (int i = 0; i < s_; ++i) {
        rhs.segment(row0 + i * (ny_ + ng_), ny_) -= h * a(i, j) * field;
      }
    }
    for (int i = 0; i < s_; ++i) {
      const PointEvaluation& stage = stages.stage(i);
      // (algebraic) G_y dy + G_p dp + G_u du.
      auto algebraic = rhs.segment(row0 + i * (ny_ + ng_) + ny_, ng_);
      if (ng_ > 0) {
        stage.G_y.MultiplyAdd(dy, algebraic);
        MultiplyAddIf(stage.G_p, dp, algebraic);
        MultiplyAddIf(stage.G_u, du, algebraic);
      }
      if (np_ == 0) continue;
      // (status) da A' + db B' with the status weights of the group.
      const auto wa = da_status_.segment(i * np_, np_);
      const auto wb = db_status_.segment(i * np_, np_);
      auto status = rhs.segment(row0 + equations + i * np_, np_);
      pair.setZero();
      stage.A_y.MultiplyAdd(dy, pair);
      MultiplyAddIf(stage.A_p, dp, pair);
      MultiplyAddIf(stage.A_u, du, pair);
      status += wa.cwiseProduct(pair);
      pair.setZero();
      stage.B_y.MultiplyAdd(dy, pair);
      MultiplyAddIf(stage.B_p, dp, pair);
      MultiplyAddIf(stage.B_u, du, pair);
      status += wb.cwiseProduct(pair);
    }
  }
  if (!setup_.with_event) return;
  // (velocity level) at the end state y_start + sum Z: its y-derivative is that of y_start.
  auto velocity = rhs.segment(setup_.elements * element_rows_, nz_);
  velocity_.equations_y.MultiplyAdd(dy, velocity);
  MultiplyAddIf(velocity_.equations_p, dp, velocity);
  MultiplyAddIf(velocity_.equations_u, du, velocity);
  // (element-length complementarity) FB weights of (h_max - h)/h_max and the indicator.
  const int event_row = num_equations();
  rhs[event_row] += event_da * h / (setup_.h_max * setup_.h_max) * dh.max;
  if (event_pair_ < 0) return;
  const int k = event_pair_;
  const int power = setup_.indicator_power[static_cast<std::size_t>(k)];
  const double weight = setup_.indicator_weights[k] / std::pow(tau_, power);
  double indicator = indicators_.d_y.Row(k).dot(dy);
  if (dp.size() > 0) indicator += indicators_.d_p.Row(k).dot(dp);
  if (du.size() > 0) indicator += indicators_.d_u.Row(k).dot(du);
  rhs[event_row] += event_db * weight * indicator;
  if (power > 0) {
    rhs[event_row] +=
        event_db * power * weight * indicators_.values[k] / setup_.h_reference * dh.reference;
  }
}

GroupSystem::LengthChanges GroupSystem::AddTransposedBlockProduct(const Vector& w, double event_da,
                                                                  double event_db,
                                                                  const ConstVectorRef& nu,
                                                                  VectorRef dy, VectorRef dp,
                                                                  VectorRef du) const {
  const double h = H(w);
  const int equations = s_ * (ny_ + ng_);
  LengthChanges lengths;
  Vector weights(ny_), pair(np_);
  for (int e = 0; e < setup_.elements; ++e) {
    const int row0 = e * element_rows_;
    const CollocationStages& stages = elements_[static_cast<std::size_t>(e)];
    const Matrix& a = stages.tableau().a;
    for (int j = 0; j < s_; ++j) {
      // (collocation) stage j enters row block i with -h a_ij.
      const PointEvaluation& stage = stages.stage(j);
      weights.setZero();
      for (int i = 0; i < s_; ++i) {
        weights -= h * a(i, j) * nu.segment(row0 + i * (ny_ + ng_), ny_);
      }
      stage.F_y.TransposedMultiplyAdd(weights, dy);
      TransposedMultiplyAddIf(stage.F_p, weights, dp);
      TransposedMultiplyAddIf(stage.F_u, weights, du);
      if (!setup_.with_event) lengths.fixed += stage.F.dot(weights) / h;
    }
    for (int i = 0; i < s_; ++i) {
      const PointEvaluation& stage = stages.stage(i);
      if (ng_ > 0) {
        const auto algebraic = nu.segment(row0 + i * (ny_ + ng_) + ny_, ng_);
        stage.G_y.TransposedMultiplyAdd(algebraic, dy);
        TransposedMultiplyAddIf(stage.G_p, algebraic, dp);
        TransposedMultiplyAddIf(stage.G_u, algebraic, du);
      }
      if (np_ == 0) continue;
      const auto status = nu.segment(row0 + equations + i * np_, np_);
      pair = da_status_.segment(i * np_, np_).cwiseProduct(status);
      stage.A_y.TransposedMultiplyAdd(pair, dy);
      TransposedMultiplyAddIf(stage.A_p, pair, dp);
      TransposedMultiplyAddIf(stage.A_u, pair, du);
      pair = db_status_.segment(i * np_, np_).cwiseProduct(status);
      stage.B_y.TransposedMultiplyAdd(pair, dy);
      TransposedMultiplyAddIf(stage.B_p, pair, dp);
      TransposedMultiplyAddIf(stage.B_u, pair, du);
    }
  }
  if (!setup_.with_event) return lengths;
  const auto velocity = nu.segment(setup_.elements * element_rows_, nz_);
  velocity_.equations_y.TransposedMultiplyAdd(velocity, dy);
  TransposedMultiplyAddIf(velocity_.equations_p, velocity, dp);
  TransposedMultiplyAddIf(velocity_.equations_u, velocity, du);
  const int event_row = num_equations();
  const double event = nu[event_row];
  lengths.max = event_da * h / (setup_.h_max * setup_.h_max) * event;
  if (event_pair_ < 0) return lengths;
  const int k = event_pair_;
  const int power = setup_.indicator_power[static_cast<std::size_t>(k)];
  const double weight = setup_.indicator_weights[k] / std::pow(tau_, power);
  const double scaled = event_db * weight * event;
  dy += scaled * indicators_.d_y.Row(k).transpose();
  if (dp.size() > 0) dp += scaled * indicators_.d_p.Row(k).transpose();
  if (du.size() > 0) du += scaled * indicators_.d_u.Row(k).transpose();
  if (power > 0) {
    lengths.reference =
        event_db * power * weight * indicators_.values[k] / setup_.h_reference * event;
  }
  return lengths;
}

}  // namespace moreau::internal
