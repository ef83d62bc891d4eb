// The collocation transcription's second-order Hessian (collocation_impl.hpp;
// OcpHessian::kSecondOrder; docs/ocp.md, "Collocation transcription"): its structure, one
// dense block per element over the element's columns plus the node functions' blocks, and its
// values from second derivatives of f, c and the costs.

#include <algorithm>
#include <cmath>

#include "collocation_impl.hpp"
#include "moreau/core/error.hpp"

namespace moreau::ocp_internal {

void CollocationNlp::Impl::BuildHessianStructure() {
  for (int k = 0; k < intervals_; ++k) {
    for (int e = 0; e < elements_; ++e) {
      hessian_columns_.push_back(MakeColumns(k, e, true, true, true, true));
      HessianBlock block;
      block.columns = hessian_columns_.back().columns;
      element_hessian_.push_back(std::move(block));
    }
  }
  for (int k = 0; k <= intervals_; ++k) {
    HessianBlock block;
    block.columns = NodeColumns(k, std::min(k, intervals_ - 1));
    node_hessian_.push_back(std::move(block));
  }
  ocp_internal::BuildHessianPattern({&element_hessian_, &node_hessian_}, &hessian_structure_);
}

void CollocationNlp::Impl::Scatter(const HessianBlock& block, const Matrix& local, Vector* values) {
  const int n = static_cast<int>(block.columns.size());
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const int position = block.position[static_cast<std::size_t>(i * n + j)];
      if (position >= 0) (*values)[position] += local(i, j);
    }
  }
}

// y = (x, t[, u, Lambda]) of stage i (i = -1: the element's start) of element (k, e).
auto CollocationNlp::Impl::PointMap(int k, int e, int i, bool with_u_lambda) const -> Map {
  const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(k * elements_ + e)];
  Map map(static_cast<std::size_t>(n_ + 1 + (with_u_lambda ? nd_ + nc_ : 0)));
  if (i < 0) {
    if (StartIsInitial(k, e)) {
      for (int f = 0; f < nf_; ++f) {
        map[static_cast<std::size_t>(
                problem_.free_initial_states[static_cast<std::size_t>(f)].state)]
            .emplace_back(layout.start + f, 1.0);
      }
    } else {
      for (int a = 0; a < n_; ++a)
        map[static_cast<std::size_t>(a)].emplace_back(layout.start + a, 1.0);
    }
    for (int m = 0; m < e; ++m)
      map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + m, 1.0);
    return map;
  }
  const int column = layout.stages + i * StageSize();
  for (int a = 0; a < n_; ++a) map[static_cast<std::size_t>(a)].emplace_back(column + a, 1.0);
  for (int m = 0; m < e; ++m)
    map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + m, 1.0);
  map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, tableau_.c[i]);
  if (with_u_lambda) {
    for (int j = 0; j < nd_; ++j) {
      map[static_cast<std::size_t>(n_ + 1 + j)].emplace_back(layout.decisions + j, 1.0);
    }
    for (int m = 0; m < nc_; ++m) {
      map[static_cast<std::size_t>(n_ + 1 + nd_ + m)].emplace_back(column + n_ + m, 1.0);
    }
  }
  return map;
}

// y = (X(theta), t(theta)) of the collocation polynomial of element (k, e) at theta in
// [0, 1], with interpolation weights w of the stages: X = (1 - sum w) x_start + sum_j w_j
// X_j, t = t_start + theta h_e (linear in the element's columns at fixed theta).
auto CollocationNlp::Impl::InterpolatedPointMap(int k, int e, const Vector& w, double theta) const
    -> Map {
  const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(k * elements_ + e)];
  Map map(static_cast<std::size_t>(n_ + 1));
  const Map start_map = PointMap(k, e, -1, false);
  for (int c = 0; c < n_; ++c) {
    for (const auto& [column, coefficient] : start_map[static_cast<std::size_t>(c)]) {
      map[static_cast<std::size_t>(c)].emplace_back(column, coefficient * (1.0 - w.sum()));
    }
    for (int j = 0; j < stages_; ++j) {
      map[static_cast<std::size_t>(c)].emplace_back(layout.stages + j * StageSize() + c, w[j]);
    }
  }
  map[static_cast<std::size_t>(n_)] = start_map[static_cast<std::size_t>(n_)];
  map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, theta);
  return map;
}

// local += D^T M D (M symmetric over y) and gradient-outer terms are the caller's.
void CollocationNlp::Impl::AddMapped(const Map& map, const Matrix& m, Matrix* local) {
  const int size = static_cast<int>(map.size());
  for (int a = 0; a < size; ++a) {
    for (const auto& [ca, wa] : map[static_cast<std::size_t>(a)]) {
      for (int b = 0; b < size; ++b) {
        const double value = m(a, b);
        if (value == 0.0) continue;
        for (const auto& [cb, wb] : map[static_cast<std::size_t>(b)]) {
          (*local)(ca, cb) += wa * wb * value;
        }
      }
    }
  }
}

// D^T g for a gradient g over y.
auto CollocationNlp::Impl::MappedGradient(const Map& map, const Vector& g, int columns) -> Vector {
  Vector out = Vector::Zero(columns);
  for (std::size_t a = 0; a < map.size(); ++a) {
    for (const auto& [c, w] : map[a]) out[c] += w * g[static_cast<Eigen::Index>(a)];
  }
  return out;
}

// Hessian over (x, t) of the moving-set constraints weighted by `weights` (n_c).
auto CollocationNlp::Impl::ConstraintHessian(const Point& p, const Vector& weights) -> Matrix {
  Matrix total = Matrix::Zero(p.x.size() + 1, p.x.size() + 1);
  for (std::size_t m = 0; m < p.c_hessians.size(); ++m) {
    if (weights[static_cast<Eigen::Index>(m)] != 0.0) {
      total += weights[static_cast<Eigen::Index>(m)] * p.c_hessians[m];
    }
  }
  return total;
}

auto CollocationNlp::Impl::Hessian(const Vector& z, double objective_factor, const Vector& lambda,
                                   Vector* values) -> bool {
  EvaluatePoints(z, true);
  values->setZero(static_cast<Eigen::Index>(hessian_structure_.size()));
  const Matrix& a = tableau_.a;
  const int y_size = n_ + 1 + nd_ + nc_;
  Matrix hessian;
  for (int k = 0; k < intervals_; ++k) {
    const Vector u = Inputs(z, k);
    for (int e = 0; e < elements_; ++e) {
      const int index = k * elements_ + e;
      const ElementColumns& layout = hessian_columns_[static_cast<std::size_t>(index)];
      const int size = static_cast<int>(layout.columns.size());
      Matrix local = Matrix::Zero(size, size);
      const double h = z[LengthIndex(k, e)];
      // (a) Collocation: mu^T R = ... - h sum_j w_j^T V_j, w_j = sum_i a_ij mu_i.
      const Vector mu = lambda.segment(CollocationRow(k, e), stages_ * n_);
      Vector d_h = Vector::Zero(size);  // gradient of -sum_j w_j^T V_j (times h: the term)
      for (int j = 0; j < stages_; ++j) {
        Vector w = Vector::Zero(n_);
        for (int i = 0; i < stages_; ++i) w += a(i, j) * mu.segment(i * n_, n_);
        if (w.lpNorm<Eigen::Infinity>() == 0.0) continue;
        const Point& p = Stage(k, e, j);
        const Map map = PointMap(k, e, j, true);
        // First derivatives of phi = w^T V over y = (x, t, u, Lambda).
        Vector g(y_size);
        g.head(n_) = p.v_x.transpose() * w;
        g[n_] = p.v_t.dot(w);
        g.segment(n_ + 1, nd_) = p.v_u.transpose() * w;
        g.tail(nc_) = p.v_lambda.transpose() * w;
        d_h -= MappedGradient(map, g, size);
        // Second derivatives of phi: f part (x, u, t) and the Lambda-(x, t) cross terms of
        // Lambda^T (grad_x c P w); the (x, t) curvature of grad_x c (third derivatives of c)
        // is left out.
        Matrix q = Matrix::Zero(y_size, y_size);
        const SmoothFunction& f = augmented_.scene.dynamics;
        if (!f.empty()) {
          f.WeightedHessian(p.x, u, p.t, parameters_, Wrt::XUT(), w, &hessian);
          // hessian over (x, u_all, t): reorder to (x, t, u_decisions).
          std::vector<int> from(static_cast<std::size_t>(n_ + 1 + nd_));
          for (int i = 0; i < n_; ++i) from[static_cast<std::size_t>(i)] = i;
          from[static_cast<std::size_t>(n_)] = n_ + nu_;
          for (int jd = 0; jd < nd_; ++jd) {
            from[static_cast<std::size_t>(n_ + 1 + jd)] = n_ + augmented_.decisions[jd];
          }
          for (int r = 0; r < n_ + 1 + nd_; ++r) {
            for (int c = 0; c < n_ + 1 + nd_; ++c) {
              q(r, c) =
                  hessian(from[static_cast<std::size_t>(r)], from[static_cast<std::size_t>(c)]);
            }
          }
        }
        for (const Set& set : sets_) {
          const Vector v = set.identity ? w : Vector(set.projection * w);
          for (int m = 0; m < set.size; ++m) {
            // d/d(x, t) of grad_x c_m . v.
            const Vector cross =
                p.c_hessians[static_cast<std::size_t>(set.offset + m)].leftCols(n_) * v;
            const int lambda_row = n_ + 1 + nd_ + set.offset + m;
            q.block(0, lambda_row, n_ + 1, 1) += cross;
            q.block(lambda_row, 0, 1, n_ + 1) += cross.transpose();
          }
        }
        AddMapped(map, -h * q, &local);
      }
      // The h_e cross terms of -h sum_j phi_j: -(e_h d^T + d e_h^T) with d = sum_j D^T g_j.
      {
        const int hc = layout.lengths + e;
        local.col(hc) += d_h;
        local.row(hc) += d_h.transpose();
      }
      // (b) Stage feasibility mu_c^T c(X_i, t_i) and (c) complementarity
      // nu_m (A_m B_m): nu_m B_m grad^2 A_m + nu_m (grad A_m grad B_m^T + transpose).
      const Vector nu = lambda.segment(ComplementarityRow(k, e), nc_);
      Vector b_sum = Vector::Zero(nc_);
      for (int i = 0; i < stages_; ++i) b_sum += z.segment(LambdaOffset(k, e, i), nc_);
      if (e > 0) b_sum += z.segment(LambdaOffset(k, e - 1, stages_ - 1), nc_);
      const Vector nu_b = nu.cwiseProduct(b_sum);
      Matrix grad_a = Matrix::Zero(size, nc_);  // columns: gradient of A_m over the block
      for (int i = -1; i < stages_; ++i) {
        const Point& p = i < 0 ? Start(k, e) : Stage(k, e, i);
        const Map map = PointMap(k, e, i, false);
        Vector weights = nu_b;
        if (i >= 0) weights += lambda.segment(FeasibilityRow(k, e) + i * nc_, nc_);
        AddMapped(map, ConstraintHessian(p, weights), &local);
        for (int m = 0; m < nc_; ++m) {
          Vector g(n_ + 1);
          g.head(n_) = p.c_x.row(m).transpose();
          g[n_] = p.c_t[m];
          grad_a.col(m) += MappedGradient(map, g, size);
        }
      }
      for (int m = 0; m < nc_; ++m) {
        if (nu[m] == 0.0) continue;
        Vector grad_b = Vector::Zero(size);
        for (int i = 0; i < stages_; ++i) grad_b[layout.stages + i * StageSize() + n_ + m] = 1.0;
        if (e > 0) grad_b[layout.previous + m] = 1.0;
        local += nu[m] * (grad_a.col(m) * grad_b.transpose() + grad_b * grad_a.col(m).transpose());
      }
      // Check points: mu_q^T c(X(theta_q), t_q), X(theta) linear in the start and the stages.
      for (int q = 0; q < NumCheckPoints(); ++q) {
        const Vector weights = lambda.segment(CheckRow(k, e) + q * nc_, nc_);
        if (weights.lpNorm<Eigen::Infinity>() == 0.0) continue;
        const Map map = InterpolatedPointMap(k, e, check_weights_[static_cast<std::size_t>(q)],
                                             check_theta_[static_cast<std::size_t>(q)]);
        AddMapped(map, ConstraintHessian(Check(k, e, q), weights), &local);
      }
      // Element minima: mu_m r with r(z) = v(theta*(z), z), v = c_m(y) / phi(theta),
      // y = (X, t) linear in z at fixed theta. r'' = y_z^T c_yy y_z / phi + g g^T
      // d theta*/dz, g = d^2 v / dtheta dz, and d theta*/dz = -g / v'' from dv/dtheta = 0
      // (interior minima; at an end of the search interval theta* is fixed). Near a flat
      // minimum the second term is large (a curvature of -1.3e4 measured at the doorway's
      // plan): without it IPOPT's model of the row is poor.
      for (int m = 0; minima_imposed_ && m < nc_; ++m) {
        if (!HasMinimumRow(k, e, m)) continue;
        const double weight = lambda[MinimumRow(k, e) + m];
        if (weight == 0.0) continue;
        const double theta = minimum_theta_[Piece(k, e, m)];
        const Vector w = tableau_.InterpolationWeights(theta);
        const Map map = InterpolatedPointMap(k, e, w, theta);
        const Point& p = MinimumPoint(k, e, m);
        const Matrix& c_yy = p.c_hessians[static_cast<std::size_t>(m)];
        const Weight phi = MinimumWeight(k, e, m);
        const double phi_value = phi.Value(theta), phi_slope = phi.Slope(theta);
        AddMapped(map, (weight / phi_value) * c_yy, &local);
        const double first = phi.start ? kPinnedMargin : 0.0;
        const double last = phi.end ? 1.0 - kPinnedMargin : 1.0;
        if (theta <= first || theta >= last) continue;
        // y' = dy/dtheta = (sum_j w'_j Z_j, h) and y''; w'' by central differences of w'
        // (exact for s <= 3, where w' is quadratic; O(1e-8) relative otherwise).
        constexpr double kDelta = 1e-4;
        const Vector dw = tableau_.InterpolationDerivativeWeights(theta);
        const Vector ddw = (tableau_.InterpolationDerivativeWeights(theta + kDelta) -
                            tableau_.InterpolationDerivativeWeights(theta - kDelta)) /
                           (2.0 * kDelta);
        const Vector& x_start = Start(k, e).x;
        Vector dy = Vector::Zero(n_ + 1), ddy = Vector::Zero(n_ + 1);
        for (int j = 0; j < stages_; ++j) {
          dy.head(n_) += dw[j] * (Stage(k, e, j).x - x_start);
          ddy.head(n_) += ddw[j] * (Stage(k, e, j).x - x_start);
        }
        dy[n_] = h;
        Vector c_y(n_ + 1);
        c_y.head(n_) = p.c_x.row(m).transpose();
        c_y[n_] = p.c_t[m];
        // v'' from c, c' and c'' (phi is at most quadratic).
        const double c_value = p.c[m], dc = c_y.dot(dy), ddc = dy.dot(c_yy * dy) + c_y.dot(ddy);
        const double curvature =
            ddc / phi_value - 2.0 * dc * phi_slope / (phi_value * phi_value) -
            c_value * phi.Curvature() / (phi_value * phi_value) +
            2.0 * c_value * phi_slope * phi_slope / (phi_value * phi_value * phi_value);
        if (!(curvature > 0.0)) continue;  // not a strict minimum: no theta* derivative
        // d y' / dz: the start with -sum_j w'_j, stage j with w'_j, t' = h_e.
        const Map start_map = PointMap(k, e, -1, false);
        Map derivative_map(static_cast<std::size_t>(n_ + 1));
        for (int c = 0; c < n_; ++c) {
          for (const auto& [column, coefficient] : start_map[static_cast<std::size_t>(c)]) {
            derivative_map[static_cast<std::size_t>(c)].emplace_back(column,
                                                                     -coefficient * dw.sum());
          }
          for (int j = 0; j < stages_; ++j) {
            derivative_map[static_cast<std::size_t>(c)].emplace_back(
                layout.stages + j * StageSize() + c, dw[j]);
          }
        }
        derivative_map[static_cast<std::size_t>(n_)].emplace_back(layout.lengths + e, 1.0);
        // d/dz of v' = c'/phi - c phi'/phi^2.
        const Vector g =
            (MappedGradient(map, c_yy * dy, size) + MappedGradient(derivative_map, c_y, size)) /
                phi_value -
            MappedGradient(map, c_y, size) * (phi_slope / (phi_value * phi_value));
        local -= (weight / curvature) * g * g.transpose();
      }
      // (d) The step-equilibration penalty.
      if (!exact_ && options_.step_equilibration_weight > 0.0) {
        const double nominal = interval_length_ / elements_;
        local(layout.lengths + e, layout.lengths + e) += objective_factor * 2.0 *
                                                         options_.step_equilibration_weight /
                                                         (nominal * nominal) / intervals_;
      }
      Scatter(element_hessian_[static_cast<std::size_t>(index)], local, values);
    }
  }
  // (e) Terminal and path functions at the nodes.
  const int last = intervals_ - 1;
  for (int k = 0; k <= intervals_; ++k) {
    const int kd = std::min(k, last);
    const Vector x = k == 0 ? InitialState(z)
                            : Vector(z.segment(StateOffset(k - 1, elements_ - 1, stages_ - 1), n_));
    const Vector u = Inputs(z, kd);
    const double t = tau_[static_cast<std::size_t>(k)];
    Matrix total = Matrix::Zero(n_ + nu_, n_ + nu_);
    auto add = [&](const SmoothFunction& f, const Vector& weights) {
      if (f.empty() || weights.lpNorm<Eigen::Infinity>() == 0.0) return;
      Wrt wrt;
      wrt.x = true;
      wrt.u = true;
      f.WeightedHessian(x, u, t, parameters_, wrt, weights, &hessian);
      total += hessian;
    };
    if (k == intervals_) {
      add(problem_.terminal_cost, Vector::Constant(1, objective_factor));
      if (num_terminal_equalities_ > 0) {
        add(problem_.terminal_equalities, lambda.segment(TerminalRow(), num_terminal_equalities_));
      }
      if (num_terminal_inequalities_ > 0) {
        add(problem_.terminal_inequalities,
            lambda.segment(TerminalRow() + num_terminal_equalities_, num_terminal_inequalities_));
      }
    }
    if (num_path_ > 0) add(problem_.path_constraints, lambda.segment(PathRow(k), num_path_));
    const HessianBlock& block = node_hessian_[static_cast<std::size_t>(k)];
    const int node = k == 0 ? nf_ : n_;
    std::vector<int> position(static_cast<std::size_t>(n_ + nu_), -1);
    if (k == 0) {
      for (int f = 0; f < nf_; ++f) {
        position[static_cast<std::size_t>(
            problem_.free_initial_states[static_cast<std::size_t>(f)].state)] = f;
      }
    } else {
      for (int i = 0; i < n_; ++i) position[static_cast<std::size_t>(i)] = i;
    }
    for (int j = 0; j < nd_; ++j)
      position[static_cast<std::size_t>(n_ + augmented_.decisions[j])] = node + j;
    Matrix local = Matrix::Zero(static_cast<Eigen::Index>(block.columns.size()),
                                static_cast<Eigen::Index>(block.columns.size()));
    for (int r = 0; r < n_ + nu_; ++r) {
      const int i = position[static_cast<std::size_t>(r)];
      if (i < 0) continue;
      for (int c = 0; c < n_ + nu_; ++c) {
        const int j = position[static_cast<std::size_t>(c)];
        if (j >= 0) local(i, j) += total(r, c);
      }
    }
    Scatter(block, local, values);
  }
  return values->allFinite();
}

}  // namespace moreau::ocp_internal
