#pragma once
// Radau IIA collocation of a lowered system over one step or finite element (private to
// moreau::integrators).
//
// Unknowns of one step, stage-interleaved: w = [Z_1; z_1; ...; Z_s; z_s], with stage states
// Y_i = y0 + Z_i (n_y each) and stage algebraic values z_i (n_z each).
// Residual rows, stage by stage:
//   collocation  Z_i - h sum_j a_ij F(Y_j, z_j) = 0      (n_y rows per stage)
//   algebraic    G(Y_i, z_i) = 0                         (n_G rows per stage)
//   pairs        (a, b) = (A(Y_i, z_i), B(Y_i, z_i))     (n_pairs per stage)
// The pair rows of a Jacobian combine da * dA + db * dB: an NCP function's derivatives for
// stage complementarity, or (1, 0)/(0, 1) for the active-set equations a = 0 / b = 0.

#include <vector>

#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau::internal {

class CollocationStages {
 public:
  CollocationStages(LoweredSystem* system, int stages);
  // Takes the lowered system's current sizes (after a change of its working set).
  void Resize();

  int stages() const { return s_; }
  int num_states() const { return ny_; }
  int num_algebraic() const { return nz_; }
  int num_equations() const { return ng_; }
  int num_pairs() const { return np_; }
  int unknowns() const { return s_ * (ny_ + nz_); }       // size of w
  int equation_rows() const { return s_ * (ny_ + ng_); }  // collocation + algebraic
  int pair_rows() const { return s_ * np_; }
  const RadauTableau& tableau() const { return tableau_; }

  // Offsets inside w of stage i's state increment and algebraic values.
  int state_offset(int i) const { return i * (ny_ + nz_); }
  int algebraic_offset(int i) const { return i * (ny_ + nz_) + ny_; }

  // Structural nonzeros of one step's Jacobian (AddJacobian): unknowns() squared with dense
  // storage; from the lowered system's block patterns with sparse storage.
  double EstimatedJacobianNonzeros() const;
  // Nonzeros that an earlier element's end adds to this element's rows (AddStartJacobian).
  double EstimatedStartNonzeros() const;

  // Evaluates all stages at Y_i = y0 + Z_i, z_i taken from w.
  void Evaluate(const ConstVectorRef& y0, const ConstVectorRef& w, Derivatives derivatives);
  const PointEvaluation& stage(int i) const { return stages_[static_cast<std::size_t>(i)]; }
  // The derivatives the last Evaluate computed (kNone: stage(i) holds values only, and its
  // derivative blocks are not those of the stage).
  Derivatives derivatives() const { return derivatives_; }
  // Stage i's evaluation if it has derivatives with respect to y and z, else null.
  const PointEvaluation* stage_with_derivatives(int i) const {
    return derivatives_ == Derivatives::kNone ? nullptr : &stage(i);
  }
  // The point (Y_i, z_i) of stage i at the last Evaluate.
  const Vector& stage_state(int i) const { return stage_y_[static_cast<std::size_t>(i)]; }
  const Vector& stage_algebraic(int i) const { return stage_z_[static_cast<std::size_t>(i)]; }

  // Residual of the collocation and algebraic rows (equation_rows()) and the pair sides
  // (pair_rows() each), for element length h, at the last Evaluate.
  void Residual(double h, const ConstVectorRef& w, VectorRef equations, VectorRef a,
                VectorRef b) const;
  // Adds the Jacobian with respect to w: equation rows at row0, pair rows at pair_row0,
  // columns at col0. da, db weight the pair rows (pair_rows() entries each).
  void AddJacobian(double h, const ConstVectorRef& da, const ConstVectorRef& db, int row0,
                   int pair_row0, int col0, SystemMatrix* jacobian) const;
  // d(equation rows)/dh = [-sum_j a_ij F_j; 0] (pair rows do not depend on h).
  Vector ResidualDerivativeH() const;
  // Adds the derivative of all rows with respect to the start state y0 (n_y columns at
  // col0): collocation -h sum_j a_ij F_y(Y_j), algebraic G_y(Y_i), pairs da A_y + db B_y.
  void AddStartJacobian(double h, const ConstVectorRef& da, const ConstVectorRef& db, int row0,
                        int pair_row0, int col0, SystemMatrix* jacobian) const;
  // Derivative of all rows (equation rows, then pair rows weighted by da, db) with respect to
  // the inputs u and parameters p, from an evaluation with Derivatives::kAll.
  void ParameterJacobian(double h, const ConstVectorRef& da, const ConstVectorRef& db, Matrix* d_u,
                         Matrix* d_p) const;

  // State at the end of the step, y0 + Z_s.
  Vector EndState(const ConstVectorRef& y0, const ConstVectorRef& w) const;
  // Stage-i algebraic values.
  Vector Algebraic(const ConstVectorRef& w, int i) const {
    return w.segment(algebraic_offset(i), nz_);
  }
  // Initial guess for w: state increments extrapolated along the previous step's
  // collocation polynomial (`previous`, its w and length h) or zero; algebraic values at
  // stage i from LoweredSystem::InitialAlgebraicGuess at the guessed stage state (so that a
  // stage predicted beyond a switching surface starts in its new mode), keeping z_previous
  // where the state does not decide. Without `algebraic` those stay zero (a caller that sets
  // them itself).
  Vector InitialGuess(const ConstVectorRef& y0, double h, const Vector* previous, double previous_h,
                      const Vector& z_previous, bool algebraic = true) const;
  // The same into *out (its storage reused; neither previous nor z_previous).
  void InitialGuess(const ConstVectorRef& y0, double h, const Vector* previous, double previous_h,
                    const Vector& z_previous, Vector* out, bool algebraic = true) const;

 private:
  LoweredSystem* system_;
  const RadauTableau& tableau_;
  int s_, ny_, nz_, ng_, np_;
  std::vector<PointEvaluation> stages_;
  std::vector<Vector> stage_y_, stage_z_;
  Derivatives derivatives_ = Derivatives::kNone;
  // Extrapolation weights for the last step-length ratio (column i: stage i of the new step).
  mutable double cached_ratio_ = -1.0;
  mutable Matrix extrapolation_;
  mutable Vector extrapolation_weights_;
  mutable Vector guess_y_, guess_z_;
  // InitialGuess without a previous step: the start's evaluation, kept across guesses. Scratch:
  // a copy or move of the stages starts without it (copying its storage would allocate where
  // the guess itself no longer does).
  struct StartScratch {
    StartScratch() = default;
    StartScratch(const StartScratch&) {}
    StartScratch(StartScratch&&) noexcept {}
    StartScratch& operator=(const StartScratch&) { return *this; }
    StartScratch& operator=(StartScratch&&) noexcept { return *this; }
    PointEvaluation evaluation;
  };
  mutable StartScratch start_;
};

}  // namespace moreau::internal
