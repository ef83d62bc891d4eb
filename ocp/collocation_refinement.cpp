// The refinement of the collocation transcription (collocation_impl.hpp;
// OcpOptions::collocation_refinement_stages; docs/ocp.md, "Refinement"): the exact level with a
// coarser transcription's pieces and element minima, and its solution carried over.

#include <algorithm>

#include "collocation_impl.hpp"
#include "moreau/core/error.hpp"

namespace moreau::ocp_internal {

// The exact level with the pieces of `coarse` (same N and N_fe, fewer stages), and its
// element minima if they are imposed there.
void CollocationNlp::Impl::SetRefinedLevel(const Impl& coarse) {
  MOREAU_ASSERT(coarse.exact_ && coarse.intervals_ == intervals_ && coarse.elements_ == elements_ &&
                    coarse.n_ == n_ && coarse.nc_ == nc_ && coarse.nd_ == nd_ && coarse.nf_ == nf_,
                "a refinement needs the coarse transcription's exact level on the same mesh");
  SetExactPieces(coarse.pieces_);
  if (coarse.minima_imposed_) ImposeElementMinimumRows(coarse.minimum_rows_, nullptr);
}

// The coarse solution zc on this transcription: decisions and element lengths as they are;
// the stage states on the coarse collocation polynomial at this tableau's nodes (element
// ends unchanged); the multipliers Lambda by the polynomial through the coarse stages
// (clamped to >= 0, zero on inactive pieces). IPOPT's multipliers (mc, if not empty) go to
// *mf where a row or bound has the same meaning in both transcriptions: the bounds of the
// decisions, free initial states and lengths, the interval-length, equilibration, terminal,
// path and element-minimum rows. The stage rows' and the Lambda bounds' multipliers start at
// zero: measured on the doorway, carrying them over as densities over the quadrature weights
// (the collocation rows' through nu = A^T mu ~ b p, p the costate) took 11 iterations to
// s = 4 and 9 to s = 5, zeros 10 and 9; all multipliers zero took 20 (s = 4), IPOPT's own
// initial multipliers (no warm start) 117.
auto CollocationNlp::Impl::Interpolate(const Impl& coarse, const Vector& zc,
                                       const OcpMultipliers& mc, OcpMultipliers* mf) const
    -> Vector {
  const RadauTableau& tc = coarse.tableau_;
  const int sc = coarse.stages_;
  // Per new stage i: the coarse polynomial's weights at c_i (over the start and the coarse
  // stages) and the Lagrange weights over the coarse nodes c_1..c_sc (Lambda has no start
  // value).
  std::vector<Vector> polynomial(static_cast<std::size_t>(stages_));
  Matrix lagrange(stages_, sc);
  for (int i = 0; i < stages_; ++i) {
    polynomial[static_cast<std::size_t>(i)] = tc.InterpolationWeights(tableau_.c[i]);
    for (int j = 0; j < sc; ++j) {
      double w = 1.0;
      for (int l = 0; l < sc; ++l) {
        if (l != j) w *= (tableau_.c[i] - tc.c[l]) / (tc.c[j] - tc.c[l]);
      }
      lagrange(i, j) = w;
    }
  }
  Vector z = Vector::Zero(variable_lower_.size());
  z.head(nf_) = zc.head(nf_);
  const bool duals = !mc.empty() && mf != nullptr;
  if (duals) {
    mf->constraints = Vector::Zero(constraint_lower_.size());
    mf->lower_bounds = Vector::Zero(z.size());
    mf->upper_bounds = Vector::Zero(z.size());
    mf->lower_bounds.head(nf_) = mc.lower_bounds.head(nf_);
    mf->upper_bounds.head(nf_) = mc.upper_bounds.head(nf_);
  }
  auto copy = [&](int fine, int from, int size) {
    z.segment(fine, size) = zc.segment(from, size);
    if (!duals) return;
    mf->lower_bounds.segment(fine, size) = mc.lower_bounds.segment(from, size);
    mf->upper_bounds.segment(fine, size) = mc.upper_bounds.segment(from, size);
  };
  Matrix states(sc, n_), lambdas(sc, nc_);
  for (int k = 0; k < intervals_; ++k) {
    copy(ControlOffset(k), coarse.ControlOffset(k), nd_);
    for (int e = 0; e < elements_; ++e) {
      copy(LengthIndex(k, e), coarse.LengthIndex(k, e), 1);
      const Vector x_start = coarse.StartIsInitial(k, e)
                                 ? coarse.InitialState(zc)
                                 : Vector(zc.segment(coarse.StartOffset(k, e), n_));
      for (int j = 0; j < sc; ++j) {
        states.row(j) = zc.segment(coarse.StateOffset(k, e, j), n_).transpose();
        lambdas.row(j) = zc.segment(coarse.LambdaOffset(k, e, j), nc_).transpose();
      }
      const Matrix lambda = lagrange * lambdas;
      for (int i = 0; i < stages_; ++i) {
        Vector x = x_start;
        for (int j = 0; j < sc; ++j) {
          x += polynomial[static_cast<std::size_t>(i)][j] * (states.row(j).transpose() - x_start);
        }
        z.segment(StateOffset(k, e, i), n_) = x;
        for (int m = 0; m < nc_; ++m) {
          z[LambdaOffset(k, e, i) + m] =
              pieces_[Piece(k, e, m)] ? std::max(0.0, lambda(i, m)) : 0.0;
        }
      }
      if (!duals) continue;
      if (minima_imposed_ && coarse.minima_imposed_ && mc.constraints.size() > coarse.NumRows()) {
        mf->constraints.segment(MinimumRow(k, e), NumMinimumRows()) =
            mc.constraints.segment(coarse.MinimumRow(k, e), coarse.NumMinimumRows());
      }
    }
    if (duals) {
      mf->constraints.segment(LengthRow(k), elements_) =
          mc.constraints.segment(coarse.LengthRow(k), elements_);
    }
  }
  if (duals) {
    const int tail = NumRows() - TerminalRow();
    mf->constraints.segment(TerminalRow(), tail) =
        mc.constraints.segment(coarse.TerminalRow(), tail);
  }
  return z;
}

}  // namespace moreau::ocp_internal
