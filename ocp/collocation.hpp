#pragma once
// Private to moreau::ocp: the complementarity-constrained collocation transcription of the
// FESD discretization (docs/ocp.md, "Collocation transcription").

#include <memory>
#include <string>
#include <vector>

#include "moreau/ocp/ocp.hpp"
#include "nlp.hpp"

namespace moreau::ocp_internal {

// The FESD discretization of a sweeping process written out as an NLP with complementarity
// constraints (Nurkanovic et al.; Pozharskiy et al., sweeping processes, eq. (9)): per control
// interval N_fe finite elements of free lengths h (summing to the interval), per element s
// Radau IIA stages with the states X and the moving-set multipliers Lambda as variables,
//
//   X_i = X_0 + h sum_j a_ij (f(X_j, u, t_j) + P grad_x c(X_j, t_j)^T Lambda_j),
//   Lambda >= 0, c(X_i, t_i) >= 0, and cross complementarity per element and constraint m:
//   (sum_{i=0..s} c_m(X_i, t_i)) (sum_j Lambda_j,m [+ Lambda_m at the previous element's end])
//   = 0,
//
// X_0 the element's start (the previous element's last stage; the initial state). Levels:
//  - relaxed (Scholtes): the products <= sigma, element lengths pulled towards H / N_fe by a
//    small penalty (their other choices do not change the trajectory where nothing switches);
//  - exact: the pieces of the last relaxed solution are fixed (per element and constraint
//    either Lambda = 0 with c >= 0, or c = 0 at every stage and the start with Lambda >= 0)
//    and elements whose boundary carries no change of the active set have equal lengths (step
//    equilibration), so complementarity holds exactly and the NLP is smooth: its solutions
//    are FESD trajectories with switches on element boundaries;
//  - element minima (ImposeElementMinima): the exact level again, with every inactive piece's
//    constraint nonnegative on the whole collocation polynomial, not only at check points.
// Only scenes whose effects are moving sets are supported (no speed of time).
class CollocationNlp final : public Nlp {
 public:
  CollocationNlp(const OcpProblem& problem, const OcpOptions& options);
  ~CollocationNlp() override;

  int num_variables() const override;
  int num_constraints() const override;
  const Vector& variable_lower() const override;
  const Vector& variable_upper() const override;
  const Vector& constraint_lower() const override;
  const Vector& constraint_upper() const override;
  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message) override;
  const std::vector<std::pair<int, int>>& JacobianStructure() const override;
  const std::vector<std::pair<int, int>>& HessianStructure() const override;
  bool Hessian(const Vector& z, double objective_factor, const Vector& lambda,
               const Vector& gradient, const Vector& jacobian_values,
               Vector* hessian_values) override;

  // A relaxed level: complementarity products <= level.complementarity (> 0), terminal
  // equalities within +-level.relaxation, the level's parameter values.
  void SetRelaxedLevel(const OcpHomotopyLevel& level);
  // The exact level with the pieces read from z (a solution of a relaxed level). Returns the
  // number of (element, constraint) pieces with the constraint active.
  int SetExactLevel(const Vector& z);
  // On the exact level, with the same pieces (OcpOptions::collocation_element_minima): every
  // inactive piece's constraint has its minimum over the element's collocation polynomial
  // >= 0 instead of c >= 0 at the check points; the check rows' multipliers (IPOPT's, one per
  // constraint; may be null) move to the minimum's row. Except pieces whose minimum at z lies
  // where an active constraint of the element has the opposite normal (the doorway's touching
  // point): they keep the check points (element_minima.cpp, OpposedToActivePiece).
  void ImposeElementMinima(const Vector& z, Vector* multipliers);
  // The refinement (OcpOptions::collocation_refinement_stages): this transcription (more
  // stages, the same problem, N and N_fe) on the exact level with the pieces of `coarse` (on
  // its exact level), and its element minima if they are imposed there.
  void SetRefinedLevel(const CollocationNlp& coarse);
  // A solution z of `coarse` (and its IPOPT multipliers, if not empty) carried to this
  // transcription: the coarse collocation polynomials evaluated at this tableau's nodes, the
  // multipliers where a row or bound exists in both (collocation_refinement.cpp).
  Vector Interpolate(const CollocationNlp& coarse, const Vector& z,
                     const OcpMultipliers& multipliers, OcpMultipliers* fine_multipliers) const;
  // Largest |cross-complementarity product| (c summed over an element's points times Lambda
  // summed over them) over elements and constraints at z.
  double ComplementarityResidual(const Vector& z);
  // Rows of the element minima (OcpOptions::collocation_element_minima) imposed at z whose
  // minimiser theta* lies at least margin inside its search interval (for the derivative
  // tests).
  std::vector<int> InteriorMinimumRows(const Vector& z, double margin);
  // Variables from a FESD simulation of the problem's initial controls (dense output at the
  // stage times of equal elements; multipliers from the velocity level).
  Vector InitialGuess();
  // Controls, grid, node states, final state, trajectory (element ends) and events (changes
  // of the active sets between elements) of z.
  void Describe(const Vector& z, OcpResult* result);

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace moreau::ocp_internal
