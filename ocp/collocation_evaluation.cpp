// The collocation transcription's evaluation (collocation_impl.hpp): the points (states,
// constraints, dynamics and their derivatives at the stages, check points and element minima),
// the objective, the constraints and their exact first derivatives as the sparse Jacobian's
// values, and the complementarity residual.

#include <algorithm>
#include <cmath>

#include "collocation_impl.hpp"
#include "moreau/core/error.hpp"

namespace moreau::ocp_internal {

void CollocationNlp::Impl::EvaluatePoint(const Vector& x, double t, const Vector& u,
                                         const Vector* lambda, bool derivatives, Point* p) {
  p->x = x;
  p->t = t;
  p->c.resize(nc_);
  Vector value;
  Matrix jacobian;
  if (derivatives) {
    p->c_x.resize(nc_, n_);
    p->c_t.resize(nc_);
  }
  for (const Set& set : sets_) {
    if (derivatives) {
      set.constraints.Jacobian(x, u, t, parameters_, Wrt::XT(), &value, &jacobian);
      p->c_x.middleRows(set.offset, set.size) = jacobian.leftCols(n_);
      p->c_t.segment(set.offset, set.size) = jacobian.col(n_);
    } else {
      set.constraints.Evaluate(x, u, t, parameters_, &value);
    }
    p->c.segment(set.offset, set.size) = value;
  }
  // Per-constraint Hessians (second-order mode): the Lambda-weighted sums below, the
  // constraint Hessians and the Lambda-(x, t) cross terms of the Lagrangian's Hessian come
  // from them without further evaluations.
  const bool second_order = derivatives && options_.hessian == OcpHessian::kSecondOrder;
  if (second_order) {
    p->c_hessians.resize(static_cast<std::size_t>(nc_));
    SparseMatrix sparse;
    for (const Set& set : sets_) {
      for (int m = 0; m < set.size; ++m) {
        Vector unit = Vector::Zero(set.size);
        unit[m] = 1.0;
        const std::vector<int> rows{m};
        set.constraints.SparseWeightedHessian(x, u, t, parameters_, Wrt::XT(), unit, &sparse,
                                              &rows);
        p->c_hessians[static_cast<std::size_t>(set.offset + m)] = Matrix(sparse);
      }
    }
  }
  if (lambda == nullptr) return;
  // V = f + sum P grad_x c^T Lambda.
  const SmoothFunction& f = augmented_.scene.dynamics;
  p->v.setZero(n_);
  if (derivatives) {
    p->v_x.setZero(n_, n_);
    p->v_t.setZero(n_);
    p->v_u.setZero(n_, nd_);
    p->v_lambda.setZero(n_, nc_);
  }
  if (!f.empty()) {
    if (derivatives) {
      f.Jacobian(x, u, t, parameters_, Wrt::XUT(), &value, &jacobian);
      p->v_x = jacobian.leftCols(n_);
      for (int j = 0; j < nd_; ++j) p->v_u.col(j) = jacobian.col(n_ + augmented_.decisions[j]);
      p->v_t = jacobian.col(n_ + nu_);
    } else {
      f.Evaluate(x, u, t, parameters_, &value);
    }
    p->v = value;
  }
  Matrix c_x_local;
  Matrix hessian;
  for (const Set& set : sets_) {
    const Vector weights = lambda->segment(set.offset, set.size);
    if (derivatives) {
      c_x_local = p->c_x.middleRows(set.offset, set.size);
    } else {
      set.constraints.Jacobian(x, u, t, parameters_, Wrt::X(), &value, &c_x_local);
    }
    const Vector push = c_x_local.transpose() * weights;
    p->v += set.identity ? push : Vector(set.projection * push);
    if (!derivatives) continue;
    if (set.identity) {
      p->v_lambda.middleCols(set.offset, set.size) = c_x_local.transpose();
    } else {
      p->v_lambda.middleCols(set.offset, set.size) = set.projection * c_x_local.transpose();
    }
    if (weights.lpNorm<Eigen::Infinity>() == 0.0) continue;
    // d/d(x, t) of grad_x c^T Lambda: the Lambda-weighted Hessian's x rows.
    if (second_order) {
      hessian.setZero(n_ + 1, n_ + 1);
      for (int m = 0; m < set.size; ++m) {
        hessian += weights[m] * p->c_hessians[static_cast<std::size_t>(set.offset + m)];
      }
    } else {
      set.constraints.WeightedHessian(x, u, t, parameters_, Wrt::XT(), weights, &hessian);
    }
    if (set.identity) {
      p->v_x += hessian.topLeftCorner(n_, n_);
      p->v_t += hessian.topRightCorner(n_, 1);
    } else {
      p->v_x += set.projection * hessian.topLeftCorner(n_, n_);
      p->v_t += set.projection * hessian.topRightCorner(n_, 1);
    }
  }
}

void CollocationNlp::Impl::EvaluatePoints(const Vector& z, bool derivatives) {
  // Evaluate and Hessian are called at the same point (IPOPT): evaluate once.
  if (points_valid_ && (points_derivatives_ || !derivatives) && z.size() == points_z_.size() &&
      z == points_z_) {
    return;
  }
  points_valid_ = false;
  points_.resize(static_cast<std::size_t>(intervals_ * elements_ * stages_));
  check_points_.resize(static_cast<std::size_t>(intervals_ * elements_ * NumCheckPoints()));
  minimum_points_.resize(static_cast<std::size_t>(intervals_ * elements_ * nc_));
  minimum_theta_.assign(static_cast<std::size_t>(intervals_ * elements_ * nc_), 0.0);
  const Vector u0 = Inputs(z, 0);
  EvaluatePoint(InitialState(z), tau_[0], u0, nullptr, derivatives, &initial_point_);
  interval_start_points_.resize(static_cast<std::size_t>(intervals_));
  for (int k = 0; k < intervals_; ++k) {
    const Vector u = Inputs(z, k);
    if (k > 0) {
      EvaluatePoint(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_),
                    tau_[static_cast<std::size_t>(k)], u, nullptr, derivatives,
                    &interval_start_points_[static_cast<std::size_t>(k)]);
    }
    for (int e = 0; e < elements_; ++e) {
      const double start = StartTime(z, k, e);
      const double h = z[LengthIndex(k, e)];
      for (int i = 0; i < stages_; ++i) {
        const Vector x = z.segment(StateOffset(k, e, i), n_);
        const Vector lambda = z.segment(LambdaOffset(k, e, i), nc_);
        EvaluatePoint(x, start + tableau_.c[i] * h, u, &lambda, derivatives, &Stage(k, e, i));
      }
      // Check points on the collocation polynomial.
      const Vector& x_start = Start(k, e).x;
      for (int q = 0; q < NumCheckPoints(); ++q) {
        Vector x = x_start;
        for (int j = 0; j < stages_; ++j) {
          x += check_weights_[static_cast<std::size_t>(q)][j] * (Stage(k, e, j).x - x_start);
        }
        EvaluatePoint(x, start + check_theta_[static_cast<std::size_t>(q)] * h, u, nullptr,
                      derivatives, &Check(k, e, q));
      }
      if (minima_imposed_) LocateMinima(k, e, start, h, u, derivatives);
    }
  }
  points_z_ = z;
  points_derivatives_ = derivatives;
  points_valid_ = true;
}

// A problem function at node k with the decisions of interval kd (columns NodeColumns).
void CollocationNlp::Impl::NodeFunction(const SmoothFunction& f, const Vector& z, int k, int kd,
                                        Vector* value, Matrix* local) const {
  const Vector x = k == 0 ? InitialState(z)
                          : Vector(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_));
  const Vector u = Inputs(z, kd);
  const double t = tau_[static_cast<std::size_t>(k)];
  if (local == nullptr) {
    f.Evaluate(x, u, t, parameters_, value);
    return;
  }
  Matrix jacobian;
  f.Jacobian(x, u, t, parameters_, Wrt::XUT(), value, &jacobian);
  const int node = k == 0 ? nf_ : n_;
  local->setZero(f.num_outputs(), node + nd_);
  if (k == 0) {
    for (int i = 0; i < nf_; ++i) {
      local->col(i) = jacobian.col(problem_.free_initial_states[static_cast<std::size_t>(i)].state);
    }
  } else {
    local->leftCols(n_) = jacobian.leftCols(n_);
  }
  for (int j = 0; j < nd_; ++j) local->col(node + j) = jacobian.col(n_ + augmented_.decisions[j]);
}

auto CollocationNlp::Impl::EquilibrationPenalty(const Vector& z, Vector* gradient) const -> double {
  if (exact_ || options_.step_equilibration_weight == 0.0) return 0.0;
  const double nominal = interval_length_ / elements_;
  double penalty = 0.0;
  for (int k = 0; k < intervals_; ++k) {
    for (int e = 0; e < elements_; ++e) {
      const double d = (z[LengthIndex(k, e)] - nominal) / nominal;
      penalty += options_.step_equilibration_weight * d * d / intervals_;
      if (gradient != nullptr) {
        (*gradient)[LengthIndex(k, e)] +=
            2.0 * options_.step_equilibration_weight * d / nominal / intervals_;
      }
    }
  }
  return penalty;
}

auto CollocationNlp::Impl::Evaluate(const Vector& z, double* objective, Vector* constraints,
                                    Vector* gradient, Vector* jacobian_values, std::string* message)
    -> bool {
  const bool derivatives = gradient != nullptr || jacobian_values != nullptr;
  EvaluatePoints(z, derivatives);
  Vector g = Vector::Zero(constraint_lower_.size());
  Vector values;
  if (derivatives) values.setZero(static_cast<Eigen::Index>(Structure().size()));
  const Matrix& a = tableau_.a;
  const Vector& cc = tableau_.c;
  for (int k = 0; k < intervals_; ++k) {
    double length_sum = 0.0;
    for (int e = 0; e < elements_; ++e) {
      const int index = k * elements_ + e;
      const double h = z[LengthIndex(k, e)];
      length_sum += h;
      const Point& start = Start(k, e);
      // (9a, 9b) Radau IIA collocation: R_i = X_i - X_0 - h sum_j a_ij V_j.
      for (int i = 0; i < stages_; ++i) {
        Vector r = Stage(k, e, i).x - start.x;
        for (int j = 0; j < stages_; ++j) r -= h * a(i, j) * Stage(k, e, j).v;
        g.segment(CollocationRow(k, e) + i * n_, n_) = r;
      }
      // Stage feasibility c(X_i, t_i) >= 0 and (9c-9f) cross complementarity.
      for (int i = 0; i < stages_; ++i) {
        g.segment(FeasibilityRow(k, e) + i * nc_, nc_) = Stage(k, e, i).c;
      }
      Vector c_sum = start.c;
      Vector lambda_sum = Vector::Zero(nc_);
      for (int i = 0; i < stages_; ++i) {
        c_sum += Stage(k, e, i).c;
        lambda_sum += z.segment(LambdaOffset(k, e, i), nc_);
      }
      if (e > 0) lambda_sum += z.segment(LambdaOffset(k, e - 1, stages_ - 1), nc_);
      g.segment(ComplementarityRow(k, e), nc_) = c_sum.cwiseProduct(lambda_sum);
      for (int q = 0; q < NumCheckPoints(); ++q) {
        g.segment(CheckRow(k, e) + q * nc_, nc_) = Check(k, e, q).c;
      }
      // Element minima of the inactive constraints (the other rows are free and stay 0).
      for (int m = 0; minima_imposed_ && m < nc_; ++m) {
        if (!HasMinimumRow(k, e, m)) continue;
        g[MinimumRow(k, e) + m] = MinimumPoint(k, e, m).c[m] /
                                  MinimumWeight(k, e, m).Value(minimum_theta_[Piece(k, e, m)]);
      }
      if (e > 0) g[EquilibrationRow(k, e)] = h - z[LengthIndex(k, e - 1)];
      if (!derivatives) continue;
      // Collocation block.
      {
        const ElementColumns& layout = collocation_columns_[static_cast<std::size_t>(index)];
        auto block = BlockValues(collocation_block_[static_cast<std::size_t>(index)], &values);
        for (int i = 0; i < stages_; ++i) {
          auto rows = block.middleRows(i * n_, n_);
          // Start state.
          if (StartIsInitial(k, e)) {
            for (int f = 0; f < nf_; ++f) {
              rows(problem_.free_initial_states[static_cast<std::size_t>(f)].state, f) -= 1.0;
            }
          } else {
            rows.middleCols(layout.start, n_) -= Matrix::Identity(n_, n_);
          }
          Vector d_h = Vector::Zero(n_);        // d/dh_e
          Vector d_earlier = Vector::Zero(n_);  // d/dh_m, m < e (through the stage times)
          for (int j = 0; j < stages_; ++j) {
            const Point& p = Stage(k, e, j);
            const double w = h * a(i, j);
            d_h -= a(i, j) * p.v + w * cc[j] * p.v_t;
            d_earlier -= w * p.v_t;
            const int column = layout.stages + j * StageSize();
            rows.middleCols(column, n_) -= w * p.v_x;
            if (i == j) rows.middleCols(column, n_) += Matrix::Identity(n_, n_);
            rows.middleCols(column + n_, nc_) -= w * p.v_lambda;
            rows.middleCols(layout.decisions, nd_) -= w * p.v_u;
          }
          for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) = d_earlier;
          rows.col(layout.lengths + e) = d_h;
        }
      }
      // Feasibility block: columns h_0..h_e, stage states.
      {
        const ElementColumns& layout = feasibility_columns_[static_cast<std::size_t>(index)];
        auto block = BlockValues(feasibility_block_[static_cast<std::size_t>(index)], &values);
        for (int i = 0; i < stages_; ++i) {
          const Point& p = Stage(k, e, i);
          auto rows = block.middleRows(i * nc_, nc_);
          rows.middleCols(layout.stages + i * n_, n_) = p.c_x;
          for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) = p.c_t;
          rows.col(layout.lengths + e) = cc[i] * p.c_t;
        }
      }
      // Complementarity block: d (c_sum .* lambda_sum).
      {
        const ElementColumns& layout = complementarity_columns_[static_cast<std::size_t>(index)];
        auto block = BlockValues(complementarity_block_[static_cast<std::size_t>(index)], &values);
        // The start point: state columns and time (earlier lengths).
        const Matrix start_x = lambda_sum.asDiagonal() * start.c_x;
        if (StartIsInitial(k, e)) {
          for (int f = 0; f < nf_; ++f) {
            block.col(f) +=
                start_x.col(problem_.free_initial_states[static_cast<std::size_t>(f)].state);
          }
        } else {
          block.middleCols(layout.start, n_) += start_x;
        }
        const Vector start_t = lambda_sum.cwiseProduct(start.c_t);
        for (int m = 0; m < e; ++m) block.col(layout.lengths + m) += start_t;
        if (e > 0) {
          block.middleCols(layout.previous, nc_) += Matrix(c_sum.asDiagonal());
        }
        for (int i = 0; i < stages_; ++i) {
          const Point& p = Stage(k, e, i);
          const int column = layout.stages + i * StageSize();
          block.middleCols(column, n_) += lambda_sum.asDiagonal() * p.c_x;
          block.middleCols(column + n_, nc_) += Matrix(c_sum.asDiagonal());
          const Vector d_t = lambda_sum.cwiseProduct(p.c_t);
          for (int m = 0; m < e; ++m) block.col(layout.lengths + m) += d_t;
          block.col(layout.lengths + e) += cc[i] * d_t;
        }
      }
      // Check points: X(theta) = (1 - sum w) X_0 + sum_j w_j X_j at t_start + theta h_e.
      if (NumCheckPoints() > 0) {
        const ElementColumns& layout = check_columns_[static_cast<std::size_t>(index)];
        auto block = BlockValues(check_block_[static_cast<std::size_t>(index)], &values);
        for (int q = 0; q < NumCheckPoints(); ++q) {
          const Point& p = Check(k, e, q);
          const Vector& w = check_weights_[static_cast<std::size_t>(q)];
          auto rows = block.middleRows(q * nc_, nc_);
          const double start_weight = 1.0 - w.sum();
          if (StartIsInitial(k, e)) {
            for (int f = 0; f < nf_; ++f) {
              rows.col(f) +=
                  start_weight *
                  p.c_x.col(problem_.free_initial_states[static_cast<std::size_t>(f)].state);
            }
          } else {
            rows.middleCols(layout.start, n_) += start_weight * p.c_x;
          }
          for (int j = 0; j < stages_; ++j)
            rows.middleCols(layout.stages + j * n_, n_) += w[j] * p.c_x;
          for (int m = 0; m < e; ++m) rows.col(layout.lengths + m) += p.c_t;
          rows.col(layout.lengths + e) += check_theta_[static_cast<std::size_t>(q)] * p.c_t;
        }
      }
      // Element minima: c_m(X(theta*), t_start + theta* h) at fixed theta* (envelope theorem:
      // dc_m/dtheta = 0 at an interior minimiser, and theta* = 0 or 1 is fixed at an end).
      if (minima_imposed_) {
        const ElementColumns& layout = check_columns_[static_cast<std::size_t>(index)];
        auto block = BlockValues(minimum_block_[static_cast<std::size_t>(index)], &values);
        for (int m = 0; m < nc_; ++m) {
          if (!HasMinimumRow(k, e, m)) continue;
          const Point& p = MinimumPoint(k, e, m);
          const double theta = minimum_theta_[Piece(k, e, m)];
          const Vector w = tableau_.InterpolationWeights(theta) /
                           MinimumWeight(k, e, m).Value(theta);  // over phi(theta*)
          auto row = block.row(m);
          const double start_weight = 1.0 / MinimumWeight(k, e, m).Value(theta) - w.sum();
          if (StartIsInitial(k, e)) {
            for (int f = 0; f < nf_; ++f) {
              row[f] += start_weight *
                        p.c_x(m, problem_.free_initial_states[static_cast<std::size_t>(f)].state);
            }
          } else {
            row.segment(layout.start, n_) += start_weight * p.c_x.row(m);
          }
          for (int j = 0; j < stages_; ++j) {
            row.segment(layout.stages + j * n_, n_) += w[j] * p.c_x.row(m);
          }
          const double c_t = p.c_t[m] / MinimumWeight(k, e, m).Value(theta);
          for (int l = 0; l < e; ++l) row[layout.lengths + l] += c_t;
          row[layout.lengths + e] += theta * c_t;
        }
      }
      if (e > 0) {
        auto block = BlockValues(
            equilibration_block_[static_cast<std::size_t>(k * (elements_ - 1) + e - 1)], &values);
        block(0, 0) = -1.0;
        block(0, 1) = 1.0;
      }
    }
    g[LengthRow(k)] = length_sum - interval_length_;
    if (derivatives) {
      BlockValues(length_block_[static_cast<std::size_t>(k)], &values).setConstant(1.0);
    }
  }
  // Objective: the cost state at T, the terminal cost, the step-equilibration penalty.
  Vector df = Vector::Zero(derivatives ? variable_lower_.size() : 0);
  const int last = intervals_ - 1;
  const std::vector<int> terminal_columns = NodeColumns(intervals_, last);
  Vector value;
  Matrix local;
  double f = 0.0;
  if (augmented_.cost_state >= 0) {
    f += z[StateOffset(last, elements_ - 1, stages_ - 1) + augmented_.cost_state];
    if (derivatives)
      df[StateOffset(last, elements_ - 1, stages_ - 1) + augmented_.cost_state] += 1.0;
  }
  if (!problem_.terminal_cost.empty()) {
    NodeFunction(problem_.terminal_cost, z, intervals_, last, &value,
                 derivatives ? &local : nullptr);
    f += value[0];
    if (derivatives) {
      for (std::size_t c = 0; c < terminal_columns.size(); ++c) {
        df[terminal_columns[c]] += local(0, static_cast<Eigen::Index>(c));
      }
    }
  }
  f += EquilibrationPenalty(z, derivatives ? &df : nullptr);
  const int num_terminal = num_terminal_equalities_ + num_terminal_inequalities_;
  Matrix terminal_local(num_terminal, static_cast<Eigen::Index>(terminal_columns.size()));
  if (num_terminal_equalities_ > 0) {
    NodeFunction(problem_.terminal_equalities, z, intervals_, last, &value,
                 derivatives ? &local : nullptr);
    g.segment(TerminalRow(), num_terminal_equalities_) = value;
    if (derivatives) terminal_local.topRows(num_terminal_equalities_) = local;
  }
  if (num_terminal_inequalities_ > 0) {
    NodeFunction(problem_.terminal_inequalities, z, intervals_, last, &value,
                 derivatives ? &local : nullptr);
    g.segment(TerminalRow() + num_terminal_equalities_, num_terminal_inequalities_) = value;
    if (derivatives) terminal_local.bottomRows(num_terminal_inequalities_) = local;
  }
  if (derivatives && terminal_block_ >= 0) BlockValues(terminal_block_, &values) = terminal_local;
  for (int k = 0; num_path_ > 0 && k <= intervals_; ++k) {
    NodeFunction(problem_.path_constraints, z, k, std::min(k, last), &value,
                 derivatives ? &local : nullptr);
    g.segment(PathRow(k), num_path_) = value;
    if (derivatives) BlockValues(path_block_[static_cast<std::size_t>(k)], &values) = local;
  }
  if (objective != nullptr) *objective = f;
  if (constraints != nullptr) *constraints = g;
  if (gradient != nullptr) *gradient = df;
  if (jacobian_values != nullptr) *jacobian_values = std::move(values);
  if (!std::isfinite(f) || !g.allFinite()) {
    if (message != nullptr) *message = "non-finite objective or constraints";
    return false;
  }
  return true;
}

auto CollocationNlp::Impl::ComplementarityResidual(const Vector& z) -> double {
  Vector g;
  Evaluate(z, nullptr, &g, nullptr, nullptr, nullptr);
  double worst = 0.0;
  for (int k = 0; k < intervals_; ++k) {
    for (int e = 0; e < elements_; ++e) {
      worst = std::max(worst, g.segment(ComplementarityRow(k, e), nc_).cwiseAbs().maxCoeff());
    }
  }
  return worst;
}

}  // namespace moreau::ocp_internal
