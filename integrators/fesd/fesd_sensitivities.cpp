#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/projection.hpp"

namespace moreau::internal {

// A switch found exactly on a step boundary was not located by an event equation, so the
// local transfers miss how its time moves with the data. The saltation matrix restores it:
// with iota the indicator of pair k under the old statuses (its total derivative includes
// the velocity-level values, v = v(y, p, u) from E(y, v, p, u) = 0), the switch time moves by
// dtau_s = -(diota)/(diota/dtau), diota/dtau = iota_y F_-, and the state at the boundary by
// (F_- - F_+) dtau_s, F_-/F_+ the fields before and after the switch.
void FesdRun::ApplySaltation(const std::vector<bool>& before, const Vector& v_before, int k) {
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  IndicatorEvaluation indicator;
  system_.EvaluateEventIndicators(y_, v_before, before, Derivatives::kAll, &indicator);
  VelocityLevelEvaluation velocity;
  system_.EvaluateVelocityLevel(y_, v_before, LoweredSystem::RolesFor(before), Derivatives::kAll,
                                &velocity);
  // Dense: sensitivities carry dense n_y-column matrices anyway.
  Eigen::RowVectorXd g_y = indicator.d_y.Row(k), g_p = indicator.d_p.Row(k),
                     g_u = indicator.d_u.Row(k);
  const Eigen::RowVectorXd g_v = nz_ > 0 ? indicator.d_v.Row(k) : Eigen::RowVectorXd();
  if (nz_ > 0 && g_v.lpNorm<Eigen::Infinity>() > 0.0) {
    const Eigen::PartialPivLU<Matrix> lu(velocity.equations_v.ToDense().transpose());
    const Eigen::RowVectorXd weights = lu.solve(Vector(g_v.transpose())).transpose();
    g_y -= weights * velocity.equations_y.ToDense();
    g_p -= weights * velocity.equations_p.ToDense();
    g_u -= weights * velocity.equations_u.ToDense();
  }
  PointEvaluation before_switch, after_switch;
  system_.Evaluate(y_, ConsistentGuess(y_, v_before), Derivatives::kNone, &before_switch);
  system_.Evaluate(y_, ConsistentGuess(y_, v()), Derivatives::kNone, &after_switch);
  const double rate = g_y.dot(before_switch.F);
  // A grazing switch (zero rate) has no derivative; leave the transfers as they are.
  if (std::fabs(rate) <= 1e-12 * (1.0 + g_y.norm() * before_switch.F.norm())) return;
  if (full_) {
    Eigen::RowVectorXd d_iota = g_y * sensitivity_.topRows(ny_);
    d_iota.segment(ny_, np) += g_p;
    d_iota.segment(ny_ + np + nu * segment_, nu) += g_u;
    sensitivity_.topRows(ny_) -= (before_switch.F - after_switch.F) * (d_iota / rate);
  }
  if (!tape_.directional && !tape_.adjoint) return;
  SaltationStep step;
  step.jump = before_switch.F - after_switch.F;
  step.g_y = g_y;
  step.g_p = g_p;
  step.g_u = g_u;
  step.rate = rate;
  step.segment = segment_;
  if (tape_.directional) ApplyForward(step, np, nu, tape_.theta, &tape_.d);
  if (tape_.adjoint) {
    tape_.bytes += sizeof(double) * static_cast<std::size_t>(2 * ny_ + np + nu);
    tape_.steps.emplace_back(std::move(step));
  }
}

// --- sensitivities ------------------------------------------------------------------------
void FesdRun::InitializeSensitivities() {
  RequireArgument(!system_.scene().dynamics.has_sparse_state_jacobian(),
                  "FESD sensitivities need dense Jacobians (hand-written sparse dynamics are "
                  "not supported)");
  InitializeTape();
  if (!full_) return;
  const int np = system_.num_parameters();
  const int nu = system_.num_inputs();
  const int segments = static_cast<int>(control_starts_.size());
  // Rows: y (n_y) and tau; columns: y0 (the lowered initial state), p, u of every segment.
  sensitivity_.setZero(ny_ + 1, ny_ + np + nu * segments);
  sensitivity_.topLeftCorner(ny_, ny_).setIdentity();
}

// Implicit function theorem on the converged system R(w; y_start, tau_start, p, u) = 0:
// dw = -R_w^{-1} (R_y dy_start + R_tau dtau_start + R_p dp + R_u du), with R_w the generalized
// Jacobian that Newton factorized at the solution. The element lengths depend on tau_start
// through h = rest / count (fixed elements), h_max = rest / m and h_ref = rest / remaining.
Transfer FesdRun::LocalTransfer(const Vector& w, int group_elements, int remaining) {
  const GroupSetup& setup = group_.setup();
  group_.EvaluateForSensitivities(w);
  double event_da = 0.0, event_db = 0.0;
  if (setup.with_event) {
    const NcpValue phi =
        FischerBurmeister((setup.h_max - group_.H(w)) / setup.h_max, group_.event_indicator());
    event_da = phi.da;
    event_db = phi.db;
  }
  GroupSystem::ParameterBlocks blocks;
  group_.SensitivityBlocks(w, event_da, event_db, &blocks);
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  const Vector d_tau = setup.with_event
                           ? Vector(-blocks.h_max / group_elements - blocks.h_reference / remaining)
                           : Vector(-blocks.h_fixed / remaining);
  Matrix rhs(blocks.y_start.rows(), ny_ + 1 + np + nu);
  rhs << blocks.y_start, d_tau, blocks.p, blocks.u;
  const LinearSolver* solver = solved_by_->last_jacobian_solver();
  MOREAU_ASSERT(solver != nullptr, "no factorized Jacobian for sensitivities");
  solver->SolveMatrix(rhs);
  const Matrix dw = -rhs;
  // y_end = y_start + sum_e Z_{e,s};  tau_end = tau_start + m h (h fixed: rest / remaining).
  Matrix local = Matrix::Zero(ny_ + 1, ny_ + 1 + np + nu);
  local.topLeftCorner(ny_, ny_).setIdentity();
  const int last = (s_ - 1) * (ny_ + nz_);
  for (int e = 0; e < setup.elements; ++e) {
    local.topRows(ny_) += dw.middleRows(group_.element_offset(e) + last, ny_);
  }
  local(ny_, ny_) = 1.0;
  if (setup.with_event) {
    local.row(ny_) += setup.elements * dw.row(group_.h_index());
  } else {
    local(ny_, ny_) -= 1.0 / remaining;
  }
  Transfer transfer;
  transfer.state = local.leftCols(ny_ + 1);
  transfer.parameters = local.middleCols(ny_ + 1, np);
  transfer.inputs = local.rightCols(nu);
  return transfer;
}

void FesdRun::ApplyTransfer(const Transfer& transfer) {
  const int np = system_.num_parameters(), nu = system_.num_inputs();
  sensitivity_ = transfer.state * sensitivity_;
  sensitivity_.middleCols(ny_, np) += transfer.parameters;
  sensitivity_.middleCols(ny_ + np + nu * segment_, nu) += transfer.inputs;
}

}  // namespace moreau::internal
