#include "collocation.hpp"

#include "moreau/core/error.hpp"

namespace moreau::internal {

CollocationStages::CollocationStages(LoweredSystem* system, int stages)
    : system_(system),
      tableau_(RadauIIA(stages)),
      s_(stages),
      ny_(system->num_states()),
      nz_(system->num_algebraic()),
      ng_(system->num_equations()),
      np_(system->num_pairs()),
      stages_(static_cast<std::size_t>(stages)),
      stage_y_(static_cast<std::size_t>(stages)),
      stage_z_(static_cast<std::size_t>(stages)),
      extrapolation_(stages, stages),  // sized now: InitialGuess allocates nothing
      extrapolation_weights_(stages) {}

void CollocationStages::Resize() {
  nz_ = system_->num_algebraic();
  ng_ = system_->num_equations();
  np_ = system_->num_pairs();
  cached_ratio_ = -1.0;
}

double CollocationStages::EstimatedJacobianNonzeros() const {
  const double n = unknowns();
  if (!system_->sparse()) return n * n;
  const LoweredSystem::Nonzeros& nz = system_->nonzeros();
  const double s = s_;
  return s * s * (nz.F_y + nz.F_z) + s * ny_ +
         s * (nz.G_y + nz.G_z + nz.A_y + nz.A_z + nz.B_y + nz.B_z);
}

double CollocationStages::EstimatedStartNonzeros() const {
  const double n = unknowns();
  if (!system_->sparse()) return n * ny_;
  const LoweredSystem::Nonzeros& nz = system_->nonzeros();
  return s_ * (s_ * nz.F_y + nz.G_y + nz.A_y + nz.B_y);
}

void CollocationStages::Evaluate(const ConstVectorRef& y0, const ConstVectorRef& w,
                                 Derivatives derivatives) {
  derivatives_ = derivatives;
  for (int i = 0; i < s_; ++i) {
    const auto k = static_cast<std::size_t>(i);
    stage_y_[k] = y0 + w.segment(state_offset(i), ny_);
    stage_z_[k] = w.segment(algebraic_offset(i), nz_);
    system_->Evaluate(stage_y_[k], stage_z_[k], derivatives, &stages_[k]);
  }
}

void CollocationStages::Residual(double h, const ConstVectorRef& w, VectorRef equations,
                                 VectorRef a, VectorRef b) const {
  const Matrix& coefficients = tableau_.a;
  const int ny = ny_;
  for (int i = 0; i < s_; ++i) {
    const int row = i * (ny_ + ng_);
    // (Radau IIA collocation) Z_i - h sum_j a_ij F(Y_j, z_j) = 0. Plain loops over the states
    // (the expressions' set-up cost more than their arithmetic), with the operations, in the
    // order, of collocation = Z_i; collocation -= (h a_ij) F_j (same bits).
    double* collocation = equations.data() + row;
    const double* z_i = w.data() + state_offset(i);
    for (int d = 0; d < ny; ++d) collocation[d] = z_i[d];
    for (int j = 0; j < s_; ++j) {
      const double c = h * coefficients(i, j);
      const double* f_j = stage(j).F.data();
      for (int d = 0; d < ny; ++d) collocation[d] -= c * f_j[d];
    }
    // algebraic equations of the lowered system at stage i: G(Y_i, z_i) = 0.
    equations.segment(row + ny_, ng_) = stage(i).G;
    // complementarity pairs of stage i.
    a.segment(i * np_, np_) = stage(i).A;
    b.segment(i * np_, np_) = stage(i).B;
  }
}

void CollocationStages::AddJacobian(double h, const ConstVectorRef& da, const ConstVectorRef& db,
                                    int row0, int pair_row0, int col0,
                                    SystemMatrix* jacobian) const {
  const Matrix& coefficients = tableau_.a;
  for (int i = 0; i < s_; ++i) {
    const int row = row0 + i * (ny_ + ng_);
    for (int j = 0; j < s_; ++j) {
      const PointEvaluation& e = stage(j);
      const double weight = -h * coefficients(i, j);
      // d collocation_i / d Z_j = delta_ij I - h a_ij F_y(Y_j);  d / d z_j = -h a_ij F_z.
      jacobian->AddDerivative(row, col0 + state_offset(j), e.F_y, weight);
      if (nz_ > 0) jacobian->AddDerivative(row, col0 + algebraic_offset(j), e.F_z, weight);
    }
    jacobian->AddDiagonal(row, col0 + state_offset(i), ny_, 1.0);
    const PointEvaluation& e = stage(i);
    if (ng_ > 0) {
      jacobian->AddDerivative(row + ny_, col0 + state_offset(i), e.G_y);
      jacobian->AddDerivative(row + ny_, col0 + algebraic_offset(i), e.G_z);
    }
    if (np_ > 0) {
      // Pair rows: da dA + db dB.
      const auto wa = da.segment(i * np_, np_);
      const auto wb = db.segment(i * np_, np_);
      const int pair_row = pair_row0 + i * np_;
      jacobian->AddWeightedRows(pair_row, col0 + state_offset(i), wa, e.A_y);
      jacobian->AddWeightedRows(pair_row, col0 + state_offset(i), wb, e.B_y);
      jacobian->AddWeightedRows(pair_row, col0 + algebraic_offset(i), wa, e.A_z);
      jacobian->AddWeightedRows(pair_row, col0 + algebraic_offset(i), wb, e.B_z);
    }
  }
}

Vector CollocationStages::ResidualDerivativeH() const {
  Vector d = Vector::Zero(equation_rows());
  for (int i = 0; i < s_; ++i) {
    for (int j = 0; j < s_; ++j) {
      d.segment(i * (ny_ + ng_), ny_) -= tableau_.a(i, j) * stage(j).F;
    }
  }
  return d;
}

void CollocationStages::AddStartJacobian(double h, const ConstVectorRef& da,
                                         const ConstVectorRef& db, int row0, int pair_row0,
                                         int col0, SystemMatrix* jacobian) const {
  const Matrix& coefficients = tableau_.a;
  for (int i = 0; i < s_; ++i) {
    const int row = row0 + i * (ny_ + ng_);
    for (int j = 0; j < s_; ++j) {
      jacobian->AddDerivative(row, col0, stage(j).F_y, -h * coefficients(i, j));
    }
    const PointEvaluation& e = stage(i);
    if (ng_ > 0) jacobian->AddDerivative(row + ny_, col0, e.G_y);
    if (np_ > 0) {
      jacobian->AddWeightedRows(pair_row0 + i * np_, col0, da.segment(i * np_, np_), e.A_y);
      jacobian->AddWeightedRows(pair_row0 + i * np_, col0, db.segment(i * np_, np_), e.B_y);
    }
  }
}

void CollocationStages::ParameterJacobian(double h, const ConstVectorRef& da,
                                          const ConstVectorRef& db, Matrix* d_u,
                                          Matrix* d_p) const {
  // Dense: sensitivities with respect to a few inputs and parameters (n_u, n_p columns).
  const int nu = stage(0).F_u.cols();
  const int np = stage(0).F_p.cols();
  d_u->setZero(equation_rows() + pair_rows(), nu);
  d_p->setZero(equation_rows() + pair_rows(), np);
  for (int i = 0; i < s_; ++i) {
    const int row = i * (ny_ + ng_);
    for (int j = 0; j < s_; ++j) {
      d_u->middleRows(row, ny_) -= h * tableau_.a(i, j) * stage(j).F_u.ToDense();
      d_p->middleRows(row, ny_) -= h * tableau_.a(i, j) * stage(j).F_p.ToDense();
    }
    const PointEvaluation& e = stage(i);
    d_u->middleRows(row + ny_, ng_) = e.G_u.ToDense();
    d_p->middleRows(row + ny_, ng_) = e.G_p.ToDense();
    const auto wa = da.segment(i * np_, np_).asDiagonal();
    const auto wb = db.segment(i * np_, np_).asDiagonal();
    d_u->middleRows(equation_rows() + i * np_, np_) = wa * e.A_u.ToDense() + wb * e.B_u.ToDense();
    d_p->middleRows(equation_rows() + i * np_, np_) = wa * e.A_p.ToDense() + wb * e.B_p.ToDense();
  }
}

Vector CollocationStages::EndState(const ConstVectorRef& y0, const ConstVectorRef& w) const {
  return y0 + w.segment(state_offset(s_ - 1), ny_);
}

Vector CollocationStages::InitialGuess(const ConstVectorRef& y0, double h, const Vector* previous,
                                       double previous_h, const Vector& z_previous,
                                       bool algebraic) const {
  Vector w;
  InitialGuess(y0, h, previous, previous_h, z_previous, &w, algebraic);
  return w;
}

void CollocationStages::InitialGuess(const ConstVectorRef& y0, double h, const Vector* previous,
                                     double previous_h, const Vector& z_previous, Vector* out,
                                     bool algebraic) const {
  MOREAU_ASSERT(out != previous && out != &z_previous, "InitialGuess: an input is the output");
  Vector& w = *out;
  w.setZero(unknowns());
  if (previous != nullptr && previous_h > 0.0) {
    // Collocation polynomial of the previous step: u(theta) = y_prev + sum_j w_j(theta) Z_j.
    // The weights depend on h / previous_h only; they are cached (constant steps).
    const double ratio = h / previous_h;
    if (ratio != cached_ratio_) {
      cached_ratio_ = ratio;
      extrapolation_.resize(s_, s_);
      for (int i = 0; i < s_; ++i) {
        const double theta = 1.0 + tableau_.c[i] * ratio;
        tableau_.InterpolationWeights(theta, &extrapolation_weights_);
        extrapolation_.col(i) = extrapolation_weights_;
        extrapolation_.col(i)[s_ - 1] -= 1.0;  // minus Z_s: increments from the new start
      }
    }
    if (1.0 + ratio <= 4.0) {  // no extrapolation far beyond the previous step
      for (int i = 0; i < s_; ++i) {
        auto zi = w.segment(state_offset(i), ny_);
        for (int j = 0; j < s_; ++j) {
          zi += extrapolation_(j, i) * previous->segment(state_offset(j), ny_);
        }
      }
    }
  } else if (z_previous.size() == nz_) {
    // No previous step: the clock's increments are still known (its rate does not depend on
    // the state), and switching functions of time alone (sin(omega t) with omega h >> 1)
    // make Newton from a frozen clock guess stagnate.
    PointEvaluation& start = start_.evaluation;  // kept: no allocation per guess
    system_->Evaluate(y0, z_previous, Derivatives::kNone, &start);
    const int clock = system_->clock_index();
    if (std::isfinite(start.F[clock])) {
      for (int i = 0; i < s_; ++i) w[state_offset(i) + clock] = h * tableau_.c[i] * start.F[clock];
    }
  }
  if (!algebraic) return;
  for (int i = 0; i < s_; ++i) {
    guess_y_ = y0 + w.segment(state_offset(i), ny_);
    system_->InitialAlgebraicGuess(guess_y_, &z_previous, &guess_z_);
    w.segment(algebraic_offset(i), nz_) = guess_z_;
  }
}

}  // namespace moreau::internal
